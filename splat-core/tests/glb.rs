//! `.glb` with `KHR_gaussian_splatting` (`splat_core::glb`), read back with the `gltf` crate (an
//! independent reader): every attribute holds the model's values in glTF's y-up frame, bit for
//! bit, and the document says what the extension asks for; `decode_glb` reads the model back
//! and names the place and problem in broken files.

use std::path::Path;

use splat_core::Splats;
use splat_core::frame::y_up_frame;
use splat_core::glb::{EXTENSION, decode_glb, encode_glb, read_glb, write_glb};

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
    // The extension stores linear scales (not Inria's log-scales).
    check(
        &format!("{EXTENSION}:SCALE"),
        "VEC3",
        (0..n).flat_map(|i| y.scale(i).to_array()).collect(),
    );
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

/// A `.glb` assembled from a JSON document and a binary chunk (for editing written files).
fn assemble(json: &serde_json::Value, bin: &[u8]) -> Vec<u8> {
    let mut text = serde_json::to_vec(json).unwrap();
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    let total = 12 + 8 + text.len() + 8 + bin.len();
    let mut out = Vec::new();
    for w in [0x4654_6c67, 2, total as u32, text.len() as u32, 0x4e4f_534a] {
        out.extend(u32::to_le_bytes(w));
    }
    out.extend(&text);
    for w in [bin.len() as u32, 0x004e_4942] {
        out.extend(u32::to_le_bytes(w));
    }
    out.extend(bin);
    out
}

/// Asserts that two models agree within f32 rounding (rotations up to sign, opacities within
/// the clamp of `splat_core::logit`).
fn assert_same_model(a: &Splats, b: &Splats) {
    assert_eq!((a.len(), a.sh_degree), (b.len(), b.sh_degree));
    for i in 0..a.len() {
        assert_eq!(a.means[i], b.means[i], "splat {i}: position");
        let d = (a.log_scales[i] - b.log_scales[i]).abs().max_element();
        assert!(
            d <= 1e-5,
            "splat {i}: log-scale {} vs {}",
            a.log_scales[i],
            b.log_scales[i]
        );
        let dot = a.rotation(i).dot(b.rotation(i)).abs();
        assert!(
            dot >= 1.0 - 1e-6,
            "splat {i}: rotation {} vs {}",
            a.rotation(i),
            b.rotation(i)
        );
        let o = a.opacity(i).clamp(1e-6, 1.0 - 1e-6);
        assert!(
            (o - b.opacity(i)).abs() <= 1e-6,
            "splat {i}: opacity {o} vs {}",
            b.opacity(i)
        );
        assert_eq!(a.sh_of(i), b.sh_of(i), "splat {i}: SH");
    }
}

#[test]
fn written_models_read_back_within_f32_rounding() {
    let s = gt();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("gt.glb");
    write_glb(&p, &s).unwrap();
    assert_same_model(&s, &read_glb(&p).unwrap());
    // Every lower degree: the bands present decide the degree read.
    for degree in 0..3 {
        let mut t = Splats::new(degree);
        for i in 0..s.len() {
            t.push(
                s.means[i],
                s.log_scales[i],
                s.rotations[i],
                s.opacity_logits[i],
                s.sh_of(i),
            );
        }
        let back = decode_glb(&p, &encode_glb(&t).unwrap()).unwrap();
        assert_same_model(&t, &back);
    }
}

#[test]
fn files_with_a_byte_stride_are_read() {
    // Another writer may interleave: POSITION read through a 16-byte stride.
    let mut s = Splats::new(0);
    for k in 0..3 {
        let v = k as f32;
        s.push(
            glam::Vec3::new(v, 2.0 * v, -v),
            glam::Vec3::splat(-v),
            [1.0, 0.0, 0.0, 0.0],
            0.5,
            &[[v; 3]],
        );
    }
    let glb = Opened::new(&encode_glb(&s).unwrap());
    let mut json = glb.json.clone();
    let mut bin = glb.bin.clone();
    let (_, _, pos) = glb.attribute("POSITION");
    let start = bin.len();
    for p in pos.chunks(3) {
        for v in p {
            bin.extend(v.to_le_bytes());
        }
        bin.extend(f32::NAN.to_le_bytes()); // padding the reader must skip
    }
    let views = json["bufferViews"].as_array_mut().unwrap();
    views.push(
        serde_json::json!({"buffer": 0, "byteOffset": start, "byteLength": 48, "byteStride": 16}),
    );
    let view = views.len() - 1;
    let acc = json["meshes"][0]["primitives"][0]["attributes"]["POSITION"]
        .as_u64()
        .unwrap();
    json["accessors"][acc as usize]["bufferView"] = view.into();
    json["buffers"][0]["byteLength"] = bin.len().into();
    let back = decode_glb(Path::new("s.glb"), &assemble(&json, &bin)).unwrap();
    assert_eq!(back.means, s.means);
}

#[test]
fn broken_files_give_errors_naming_the_place_and_problem() {
    let mut s = Splats::new(1);
    for k in 0..4 {
        s.push(
            glam::Vec3::splat(k as f32),
            glam::Vec3::ZERO,
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            &[[0.1; 3]; 4],
        );
    }
    let good = encode_glb(&s).unwrap();
    let path = Path::new("bad.glb");
    let err = |bytes: &[u8]| decode_glb(path, bytes).unwrap_err().to_string();
    let expect = |bytes: &[u8], parts: &[&str]| {
        let e = err(bytes);
        assert!(e.starts_with("bad.glb: "), "{e}");
        for p in parts {
            assert!(e.contains(p), "`{p}` not in: {e}");
        }
    };
    let mut b = good.clone();
    b[0] = b'x';
    expect(&b, &["header", "magic", "not a binary glTF"]);
    expect(&good[..8], &["header", "shorter than the 12-byte"]);
    // Cut short: the header's length is more than the file holds.
    expect(
        &good[..good.len() - 4],
        &["header", "declares", "cut short"],
    );
    // A lying header length is refused without allocating it.
    let mut b = good.clone();
    b[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
    expect(&b, &["header", "declares 4294967295 bytes"]);
    // A chunk longer than the file: the JSON chunk claims everything.
    let mut b = good.clone();
    b[12..16].copy_from_slice(&(u32::MAX - 64).to_le_bytes());
    expect(&b, &["JSON chunk", "cut short"]);

    let glb = Opened::new(&good);
    let edit = |f: &dyn Fn(&mut serde_json::Value)| {
        let mut json = glb.json.clone();
        f(&mut json);
        assemble(&json, &glb.bin)
    };
    let attr = |json: &serde_json::Value, name: &str| {
        json["meshes"][0]["primitives"][0]["attributes"][name]
            .as_u64()
            .unwrap() as usize
    };
    let scale = format!("{EXTENSION}:SCALE");
    let (scale_acc, pos_acc) = (attr(&glb.json, &scale), attr(&glb.json, "POSITION"));
    expect(
        &edit(&|j| j["accessors"][scale_acc]["count"] = 3.into()),
        &[
            "accessor 2",
            ":SCALE",
            "count Some(3) does not match POSITION's 4",
        ],
    );
    expect(
        &edit(&|j| j["accessors"][pos_acc]["count"] = 1_000_000_000_000u64.into()),
        &["accessor 0 (POSITION)", "count 1000000000000"],
    );
    expect(
        &edit(&|j| j["accessors"][scale_acc]["byteOffset"] = 40.into()),
        &[
            ":SCALE",
            "4 elements need 88 bytes of bufferView 2, which has 48",
        ],
    );
    expect(
        &edit(&|j| j["bufferViews"][0]["byteOffset"] = u64::MAX.into()),
        &["bufferView 0", "outside the"],
    );
    expect(
        &edit(&|j| j["meshes"][0]["primitives"][0]["mode"] = 4.into()),
        &["mesh 0 primitive 0", "mode 4"],
    );
    expect(
        &edit(&|j| {
            j["meshes"][0]["primitives"][0]["attributes"]
                .as_object_mut()
                .unwrap()
                .remove(&format!("{EXTENSION}:SH_DEGREE_1_COEF_2"));
        }),
        &["SH degree 1 lacks", "SH_DEGREE_1_COEF_2"],
    );
    expect(
        &edit(&|j| j["nodes"][0]["translation"] = serde_json::json!([1, 2, 3])),
        &["node 0", "translation"],
    );
    expect(
        &edit(&|j| j["meshes"][0]["primitives"][0]["extensions"] = serde_json::json!({})),
        &["meshes", "no primitive with the KHR_gaussian_splatting"],
    );
    // NaN in the binary chunk: the splat and the attribute's component.
    let (_, _, pos) = glb.attribute("POSITION");
    let at = glb
        .bin
        .windows(4)
        .position(|w| w == pos[7].to_le_bytes())
        .unwrap();
    let mut bin = glb.bin.clone();
    bin[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    let e = decode_glb(path, &assemble(&glb.json, &bin))
        .unwrap_err()
        .to_string();
    assert_eq!(e, "bad.glb: vertex 2, property POSITION[1]: NaN");
    // A zero scale has no log-scale.
    let view =
        &glb.json["bufferViews"][glb.json["accessors"][2]["bufferView"].as_u64().unwrap() as usize];
    let at = view["byteOffset"].as_u64().unwrap() as usize;
    let mut bin = glb.bin.clone();
    bin[at..at + 4].copy_from_slice(&0.0f32.to_le_bytes());
    expect(
        &assemble(&glb.json, &bin),
        &[":SCALE", "splat 0: scale 0", "positive"],
    );
}
