//! `.glb` with `KHR_gaussian_splatting` (`splat_core::glb`), read back with the `gltf` crate (an
//! independent reader): every attribute holds the model's values in glTF's y-up frame, bit for
//! bit, and the document says what the extension asks for.

use std::path::Path;

use splat_core::Splats;
use splat_core::frame::y_up_frame;
use splat_core::glb::{EXTENSION, encode_glb, write_glb};

fn gt() -> Splats {
    splat_core::ply::read_splats(Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../testdata/splat-scene/gt.ply"
    )))
    .unwrap()
}

/// A `.glb` opened with the `gltf` crate's container reader (`gltf::Glb`): its JSON document and
/// binary chunk. The attribute names of `KHR_gaussian_splatting` are not core glTF 2.0 semantics,
/// which the crate's validating document reader refuses, so accessors are followed through the
/// JSON here.
struct Opened {
    json: serde_json::Value,
    bin: Vec<u8>,
}

impl Opened {
    fn new(bytes: &[u8]) -> Self {
        let glb = gltf::Glb::from_slice(bytes).unwrap();
        Self {
            json: serde_json::from_slice(&glb.json).unwrap(),
            bin: glb.bin.unwrap().into_owned(),
        }
    }

    fn primitive(&self) -> &serde_json::Value {
        &self.json["meshes"][0]["primitives"][0]
    }

    /// The accessor of `semantic`: its count, type and values (floats as f32, bytes as they are).
    fn attribute(&self, semantic: &str) -> (usize, String, Vec<f32>) {
        let index = self.primitive()["attributes"][semantic]
            .as_u64()
            .unwrap_or_else(|| panic!("no attribute {semantic}")) as usize;
        let acc = &self.json["accessors"][index];
        let view = &self.json["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
        let start = view["byteOffset"].as_u64().unwrap_or(0) as usize
            + acc["byteOffset"].as_u64().unwrap_or(0) as usize;
        let data = &self.bin[start..start + view["byteLength"].as_u64().unwrap() as usize];
        let values = match acc["componentType"].as_u64().unwrap() {
            5126 => data
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect(),
            5121 => data.iter().map(|&b| f32::from(b)).collect(),
            other => panic!("{semantic}: unexpected component type {other}"),
        };
        (
            acc["count"].as_u64().unwrap() as usize,
            acc["type"].as_str().unwrap().to_string(),
            values,
        )
    }
}

#[test]
fn every_attribute_reads_back_exactly_in_the_y_up_frame() {
    let s = gt();
    let glb = Opened::new(&encode_glb(&s).unwrap());
    assert_eq!(glb.json["extensionsUsed"][0], EXTENSION);
    assert_eq!(glb.json["asset"]["version"], "2.0");
    let prim = glb.primitive();
    assert_eq!(prim["mode"], 0, "POINTS");
    let ext = &prim["extensions"][EXTENSION];
    assert_eq!(ext["kernel"], "ellipse");
    assert_eq!(ext["colorSpace"], "srgb_rec709_display");

    let y = y_up_frame(&s);
    let n = s.len();
    let k = s.coeffs_per_splat();
    let flat3 = |v: &[glam::Vec3]| v.iter().flat_map(|x| x.to_array()).collect::<Vec<f32>>();
    let check = |semantic: &str, kind: &str, want: Vec<f32>| {
        let (count, dims, got) = glb.attribute(semantic);
        assert_eq!((count, dims.as_str()), (n, kind), "{semantic}");
        assert_eq!(got, want, "{semantic}");
    };
    check("POSITION", "VEC3", flat3(&y.means));
    check(&format!("{EXTENSION}:SCALE"), "VEC3", flat3(&y.log_scales));
    check(
        &format!("{EXTENSION}:ROTATION"),
        "VEC4",
        (0..n).flat_map(|i| y.rotation(i).to_array()).collect(),
    );
    check(
        &format!("{EXTENSION}:OPACITY"),
        "SCALAR",
        (0..n).map(|i| s.opacity(i)).collect(),
    );
    for degree in 0..=3_usize {
        for coef in 0..2 * degree + 1 {
            check(
                &format!("{EXTENSION}:SH_DEGREE_{degree}_COEF_{coef}"),
                "VEC3",
                (0..n)
                    .flat_map(|i| y.sh[i * k + degree * degree + coef])
                    .collect(),
            );
        }
    }
    assert_eq!(
        prim["attributes"].as_object().unwrap().len(),
        2 + 3 + 16,
        "POSITION, COLOR_0, scale, rotation, opacity, 16 SH"
    );
    // The fallback colour: the diffuse colour and the opacity as normalised bytes.
    let (_, kind, color) = glb.attribute("COLOR_0");
    assert_eq!(kind, "VEC4");
    for i in 0..n {
        let rgb = splat_core::sh_dc_to_rgb(s.sh[i * k]);
        let want =
            [rgb[0], rgb[1], rgb[2], s.opacity(i)].map(|v| (v.clamp(0.0, 1.0) * 255.0).round());
        assert_eq!(&color[4 * i..4 * i + 4], &want, "splat {i}");
    }
    // POSITION carries its bounds, as glTF requires.
    let pos = &glb.json["accessors"][prim["attributes"]["POSITION"].as_u64().unwrap() as usize];
    for a in 0..3 {
        let axis = y.means.iter().map(|m| m[a]);
        assert_eq!(
            pos["min"][a].as_f64().unwrap() as f32,
            axis.clone().fold(f32::INFINITY, f32::min)
        );
        assert_eq!(
            pos["max"][a].as_f64().unwrap() as f32,
            axis.fold(f32::NEG_INFINITY, f32::max)
        );
    }
}

#[test]
fn a_degree_0_model_has_only_the_dc_band_and_files_are_written_atomically() {
    let mut s = Splats::new(0);
    s.push(
        glam::Vec3::ONE,
        glam::Vec3::ZERO,
        [1.0, 0.0, 0.0, 0.0],
        0.0,
        &[[0.1, 0.2, 0.3]],
    );
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("one.glb");
    write_glb(&p, &s).unwrap();
    let glb = Opened::new(&std::fs::read(&p).unwrap());
    assert_eq!(glb.primitive()["attributes"].as_object().unwrap().len(), 6);
    assert_eq!(glb.attribute("POSITION").2, [1.0, -1.0, -1.0]);
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn models_glb_cannot_hold_are_refused() {
    let e = encode_glb(&Splats::new(0)).unwrap_err().to_string();
    assert!(e.contains("empty model"), "{e}");
    let mut s = Splats::new(0);
    s.push(
        glam::Vec3::ONE,
        glam::Vec3::ZERO,
        [1.0, 0.0, 0.0, 0.0],
        f32::NAN,
        &[[0.0; 3]],
    );
    s.push(
        glam::Vec3::ONE,
        glam::Vec3::ZERO,
        [1.0, 0.0, 0.0, 0.0],
        0.0,
        &[[0.0; 3]],
    );
    let e = encode_glb(&s).unwrap_err().to_string();
    assert!(e.contains("splat 0") && e.contains("non-finite"), "{e}");
}
