//! The viewer's shaders and scripts restate splat-core's constants (GLSL and JavaScript cannot
//! import them): each is pinned here to splat-core's value, so a change there fails until the
//! viewer follows.

use splat_core::{constants, sh};
use splat_viewer::assets;

/// The value of `const float NAME = VALUE;` (or `const NAME = VALUE;`), VALUE a number or a
/// quotient of two.
fn constant(source: &str, name: &str) -> f32 {
    let line = source
        .lines()
        .find(|l| {
            let l = l.trim_start();
            l.starts_with(&format!("const float {name} = "))
                || l.starts_with(&format!("const {name} = "))
        })
        .unwrap_or_else(|| panic!("no constant {name}"));
    let value = line.split('=').nth(1).unwrap().trim();
    let value = value.split(';').next().unwrap().trim();
    match value.split_once('/') {
        Some((a, b)) => a.trim().parse::<f32>().unwrap() / b.trim().parse::<f32>().unwrap(),
        None => value.parse().unwrap(),
    }
}

#[test]
fn rasteriser_constants_match_splat_core() {
    let vert = assets::source("splat.vert").unwrap();
    let frag = assets::source("splat.frag").unwrap();
    let js = assets::viewer_js();
    assert_eq!(constant(vert, "DILATION"), constants::DILATION);
    assert_eq!(constant(vert, "MIN_ALPHA"), constants::MIN_ALPHA);
    assert_eq!(constant(frag, "MIN_ALPHA"), constants::MIN_ALPHA);
    assert_eq!(constant(frag, "MAX_ALPHA"), constants::MAX_ALPHA);
    assert_eq!(constant(vert, "NEAR_PLANE"), constants::NEAR_PLANE);
    assert_eq!(constant(&js, "NEAR_PLANE"), constants::NEAR_PLANE);
    assert_eq!(
        constant(&js, "FOV_CLAMP_MARGIN"),
        constants::FOV_CLAMP_MARGIN
    );
}

#[test]
fn sh_constants_match_splat_core() {
    let vert = assets::source("splat.vert").unwrap();
    assert_eq!(constant(vert, "SH_C0"), sh::C0);
    assert_eq!(constant(vert, "SH_C1"), sh::C1);
    for (k, c) in sh::C2.iter().enumerate() {
        assert_eq!(constant(vert, &format!("SH_C2_{k}")), *c, "C2[{k}]");
    }
    for (k, c) in sh::C3.iter().enumerate() {
        assert_eq!(constant(vert, &format!("SH_C3_{k}")), *c, "C3[{k}]");
    }
}

#[test]
fn the_bundle_loads_nothing_from_the_network() {
    let js = assets::viewer_js();
    for file in [js.as_str(), assets::INDEX_HTML, assets::STYLE] {
        for needle in ["http://", "https://", "//cdn", "import(", "importScripts"] {
            assert!(!file.contains(needle), "{needle} in the viewer");
        }
    }
}
