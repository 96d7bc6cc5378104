//! `transcode view MODEL_OR_OUTDIR [--host ADDR] [--port N] [--colmap DIR]`: serves the splat
//! viewer on this machine and prints its address: an output folder's report and viewer as they
//! are, or any 3DGS PLY or SPZ file (with cameras to jump to from a COLMAP model).

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use splat_viewer::{SceneView, Server, Site, ViewImages, model_site};

/// Arguments of `transcode view`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A 3DGS model (.ply or .spz), or an output folder of `transcode run` or `demo` (its report
    /// with the viewer is served, and nothing outside the folder).
    pub path: PathBuf,
    /// Address to listen on. The default is reachable from this machine only; an address such
    /// as 0.0.0.0 shows the folder to the whole network.
    #[arg(long, default_value_t = IpAddr::V4(Ipv4Addr::LOCALHOST))]
    pub host: IpAddr,
    /// Port to listen on (0: any free port).
    #[arg(long, default_value_t = 0)]
    pub port: u16,
    /// For a model file: cameras to jump to, from a COLMAP model (a folder with cameras and
    /// images files, or a dataset root holding sparse/0); a dataset's images become the
    /// reference pictures to compare with.
    #[arg(long)]
    pub colmap: Option<PathBuf>,
}

/// Pages an output folder may hold, in the order they are looked for.
const ENTRY_PAGES: [&str; 5] = [
    "report/report.html",
    "report.html",
    "sequence.html",
    "viewer/index.html",
    "index.html",
];

/// Models an output folder may hold, when it has no page.
const MODELS: [&str; 2] = ["model/splats.spz", "model/splats.ply"];

/// Serves until the process is stopped.
pub fn run(args: Args) -> anyhow::Result<()> {
    let (site, what, entry) = if args.path.is_dir() {
        folder_site(&args.path, args.colmap.as_deref())?
    } else {
        let site = file_site(&args.path, args.colmap.as_deref())?;
        (
            site,
            args.path.display().to_string(),
            "index.html".to_string(),
        )
    };
    let server = Server::bind(SocketAddr::new(args.host, args.port), site)?;
    let addr = server.local_addr()?;
    println!("serving {what}");
    println!("open http://{addr}/{entry}   (Ctrl-C stops the server)");
    if !args.host.is_loopback() {
        println!(
            "note: listening on {}, so other machines on the network can read these files",
            args.host
        );
    }
    server.run()?;
    Ok(())
}

/// An output folder: its page if it has one (the folder is the root), else its model.
fn folder_site(dir: &Path, colmap: Option<&Path>) -> anyhow::Result<(Site, String, String)> {
    if let Some(entry) = ENTRY_PAGES.iter().find(|p| dir.join(p).is_file()) {
        if colmap.is_some() {
            bail!(
                "--colmap applies to a model file; {} has its own cameras",
                dir.display()
            );
        }
        let site = Site::new(*entry).with_root(dir)?;
        return Ok((site, dir.display().to_string(), (*entry).to_string()));
    }
    match MODELS.iter().map(|m| dir.join(m)).find(|p| p.is_file()) {
        Some(model) => Ok((
            file_site(&model, colmap)?,
            model.display().to_string(),
            "index.html".to_string(),
        )),
        None => bail!(
            "{} has no report or viewer page ({}) and no model ({})",
            dir.display(),
            ENTRY_PAGES.join(", "),
            MODELS.join(", ")
        ),
    }
}

/// The viewer of one model file, in memory: the viewer's files, the model and the reference
/// pictures of `colmap`'s cameras; nothing else is served.
fn file_site(model: &Path, colmap: Option<&Path>) -> anyhow::Result<Site> {
    let ext = model
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    if ext != "ply" && ext != "spz" {
        bail!(
            "{}: the viewer reads 3DGS PLY and SPZ files (.ply, .spz)",
            model.display()
        );
    }
    // Read as a model first: a point cloud, a mesh or a broken file is refused here with what
    // it is, rather than served to a viewer that then shows nothing.
    splat_core::model_file::read_model(model).map_err(super::config::flat)?;
    let mut bytes = std::fs::read(model).with_context(|| format!("reading {}", model.display()))?;
    if ext == "spz" && bytes.starts_with(b"NGSP") {
        bytes = spz_v4_as_v3(model, &bytes)?;
    }
    let (views, pictures) = match colmap {
        Some(dir) => colmap_views(dir)?,
        None => (Vec::new(), Vec::new()),
    };
    let title = format!("splats: {}", model.display());
    let mut site = model_site(&title, &format!("model.{ext}"), bytes, views)?;
    for (name, bytes) in pictures {
        site.add(&name, bytes);
    }
    Ok(site)
}

/// A version 4 SPZ (zstd streams, which browsers do not decompress) re-packed as version 3 for
/// the viewer: the same quantised values (the stored fractional bits, SH bytes kept whole, the
/// render mode), so it draws as the file does.
fn spz_v4_as_v3(model: &Path, bytes: &[u8]) -> anyhow::Result<Vec<u8>> {
    use splat_core::spz;
    let m = spz::decode_spz(model, bytes)?;
    let options = spz::SpzOptions {
        sh1_bits: 8,
        sh_rest_bits: 8,
        fractional_bits: Some(m.fractional_bits),
        antialiased: m.antialiased,
        version: spz::VERSION,
    };
    Ok(spz::encode_spz(&m.splats, &options)?)
}

/// Files to serve from memory: (path, content).
type Pictures = Vec<(String, Vec<u8>)>;

/// The cameras of a COLMAP model as the viewer's views, and the images beside them (a dataset's
/// `images/`) as reference pictures.
fn colmap_views(dir: &Path) -> anyhow::Result<(Vec<SceneView>, Pictures)> {
    let model = super::render::model_dir(dir);
    let rec = colmap_io::read_model(&model)
        .with_context(|| format!("reading the COLMAP model in {}", model.display()))?;
    // Served to whoever reaches the port: only files inside images/, whatever the names say
    // and wherever links in the folder lead.
    let images_dir = dir.join("images").canonicalize().ok();
    let inside = |image: &colmap_io::ImageRecord| {
        let images_dir = images_dir.as_ref()?;
        let file = images_dir
            .join(image.relative_file()?)
            .canonicalize()
            .ok()?;
        file.starts_with(images_dir).then_some(file)
    };
    let mut views = Vec::new();
    let mut pictures = Vec::new();
    for (id, image) in &rec.images {
        let camera = rec
            .camera_of(*id)
            .with_context(|| format!("camera of image {}", image.name))?;
        let stem = Path::new(&image.name).file_stem().map_or_else(
            || format!("image_{id}"),
            |s| s.to_string_lossy().into_owned(),
        );
        let reference = inside(image)
            .and_then(|file| std::fs::read(file).ok())
            .map(|bytes| {
                let name = format!("references/{id}-{}", sanitise(&image.name));
                pictures.push((name.clone(), bytes));
                name
            });
        views.push(SceneView {
            name: stem,
            camera: transcode::viewer::view_camera(&camera),
            images: reference.map(|r| ViewImages {
                reference: Some(r),
                render: None,
                error: None,
            }),
        });
    }
    Ok((views, pictures))
}

/// A file name with only letters, digits, `.`, `-` and `_` (others become `_`), no leading dot.
fn sanitise(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_') {
                c
            } else {
                '_'
            }
        })
        .collect();
    s.trim_start_matches('.').to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use splat_core::spz;

    #[test]
    fn a_version_4_spz_is_served_as_version_3_holding_the_same_values() {
        let gt = Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../testdata/splat-scene/gt.ply"
        ));
        let splats = splat_core::ply::read_splats(gt).unwrap();
        let options = spz::SpzOptions {
            antialiased: true,
            version: spz::ZSTD_VERSION,
            ..spz::SpzOptions::default()
        };
        let v4 = spz::encode_spz(&splats, &options).unwrap();
        let v3 = spz_v4_as_v3(Path::new("m.spz"), &v4).unwrap();
        assert_eq!(&v3[..2], &[0x1f, 0x8b], "a gzip stream");
        let (a, b) = (
            spz::decode_spz(Path::new("v4"), &v4).unwrap(),
            spz::decode_spz(Path::new("v3"), &v3).unwrap(),
        );
        assert_eq!((a.version, b.version), (4, 3));
        assert!(b.antialiased);
        assert_eq!(a.fractional_bits, b.fractional_bits);
        let (a, b) = (a.splats, b.splats);
        assert_eq!(a.means, b.means);
        assert_eq!(a.log_scales, b.log_scales);
        assert_eq!(a.sh, b.sh);
        for i in 0..a.len() {
            assert!((a.opacity(i) - b.opacity(i)).abs() < 1e-6, "splat {i}");
            // Re-packing a smallest-three quaternion lands on the same word or its neighbour.
            let angle = 2.0 * a.rotation(i).dot(b.rotation(i)).abs().min(1.0).acos();
            assert!(angle < 4e-3, "splat {i}: {angle} rad");
        }
    }

    /// A point cloud (or a broken model) named as a model is refused with what it is: it was
    /// served, and the viewer showed nothing.
    #[test]
    fn a_point_cloud_is_not_served_as_a_model() {
        let dir = tempfile::tempdir().unwrap();
        let cloud = dir.path().join("cloud.ply");
        let positions = (0..10)
            .map(|i| glam::Vec3::new(i as f32, 0.0, 1.0))
            .collect();
        plenoptic_io::write_cloud(
            &cloud,
            &plenoptic_io::PlenopticCloud {
                colors: vec![[0.5; 3]; 10],
                positions,
                ..Default::default()
            },
        )
        .unwrap();
        let e = format!("{:#}", file_site(&cloud, None).err().unwrap());
        assert!(
            e.contains("cloud.ply: PLY header: not a 3D Gaussian Splatting model"),
            "{e}"
        );
        let broken = dir.path().join("broken.spz");
        std::fs::write(&broken, b"not gzip").unwrap();
        assert!(file_site(&broken, None).is_err());
        let gt = Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../testdata/splat-scene/gt.ply"
        ));
        assert!(file_site(gt, None).is_ok());
    }

    /// Only files inside the dataset's images/ are served: names with `..` or absolute paths,
    /// and links in images/ that lead out, were read and served to whoever reached the port.
    #[cfg(unix)]
    #[test]
    fn colmap_references_stay_inside_the_images_folder() {
        let dir = tempfile::tempdir().unwrap();
        let secret = dir.path().join("secret.png");
        std::fs::write(&secret, b"secret").unwrap();
        let dataset = dir.path().join("dataset");
        let images = dataset.join("images");
        std::fs::create_dir_all(&images).unwrap();
        std::fs::write(images.join("ok.png"), b"reference").unwrap();
        std::os::unix::fs::symlink(&secret, images.join("link.png")).unwrap();
        let names = [
            "ok.png",
            "../secret.png",
            "link.png",
            secret.to_str().unwrap(),
        ];
        let sparse = dataset.join("sparse/0");
        std::fs::create_dir_all(&sparse).unwrap();
        std::fs::write(sparse.join("cameras.txt"), "1 PINHOLE 8 8 8 8 4 4\n").unwrap();
        let lines: String = names
            .iter()
            .enumerate()
            .map(|(i, n)| format!("{} 1 0 0 0 0 0 0 1 {n}\n\n", i + 1))
            .collect();
        std::fs::write(sparse.join("images.txt"), lines).unwrap();
        std::fs::write(sparse.join("points3D.txt"), "").unwrap();
        let (views, pictures) = colmap_views(&dataset).unwrap();
        assert_eq!(views.len(), 4);
        let served: Vec<&[u8]> = pictures.iter().map(|(_, b)| b.as_slice()).collect();
        assert_eq!(served, [b"reference".as_slice()]);
    }
}
