//! The viewer's files, embedded in the crate: the page, its style sheet and one script bundled
//! from the JavaScript parts, the shaders and the sort worker's source.

/// The stand-alone viewer page (`index.html`), loading `scene.js` and `viewer.js` beside it.
pub const INDEX_HTML: &str = include_str!("../assets/index.html");
/// The viewer's style sheet (`viewer.css`).
pub const STYLE: &str = include_str!("../assets/viewer.css");

/// The JavaScript parts, in the order they are bundled (each uses only those before it, and the
/// last one starts the page).
const SCRIPTS: [(&str, &str); 6] = [
    ("formats.js", include_str!("../assets/js/formats.js")),
    ("sort.js", include_str!("../assets/js/sort.js")),
    ("camera.js", include_str!("../assets/js/camera.js")),
    ("renderer.js", include_str!("../assets/js/renderer.js")),
    ("sorter.js", include_str!("../assets/js/sorter.js")),
    ("app.js", include_str!("../assets/js/app.js")),
];

/// Sources the script needs as text: the shaders (compiled by WebGL) and the worker (started
/// from a blob, which also works from a page opened from disk).
const SOURCES: [(&str, &str); 6] = [
    ("splat.vert", include_str!("../assets/glsl/splat.vert")),
    ("splat.frag", include_str!("../assets/glsl/splat.frag")),
    (
        "composite.vert",
        include_str!("../assets/glsl/composite.vert"),
    ),
    (
        "composite.frag",
        include_str!("../assets/glsl/composite.frag"),
    ),
    ("sort.js", include_str!("../assets/js/sort.js")),
    (
        "sort-worker.js",
        include_str!("../assets/js/sort-worker.js"),
    ),
];

/// Returns the text of a shader or worker source by file name (`splat.vert`, …).
#[must_use]
pub fn source(name: &str) -> Option<&'static str> {
    SOURCES.iter().find(|(n, _)| *n == name).map(|(_, s)| *s)
}

/// Returns `viewer.js`: the sources as a JSON object of strings, then the parts, in one
/// function scope.
#[must_use]
pub fn viewer_js() -> String {
    let sources: serde_json::Map<String, serde_json::Value> = SOURCES
        .iter()
        .map(|(n, s)| ((*n).to_string(), serde_json::Value::from(*s)))
        .collect();
    let mut out = String::from(
        "// The splat viewer (the splat-viewer crate's assets/, bundled). Nothing here loads\n\
         // from the network.\n(function () {\n'use strict';\nconst VIEWER_SOURCES = ",
    );
    out.push_str(&serde_json::Value::Object(sources).to_string());
    out.push_str(";\n");
    for (name, text) in SCRIPTS {
        out.push_str(&format!("\n// ---- {name}\n"));
        out.push_str(text);
    }
    out.push_str("})();\n");
    out
}

/// Returns the viewer's static files as (name, content): `index.html`, `viewer.css`, `viewer.js`.
#[must_use]
pub fn files() -> [(&'static str, String); 3] {
    [
        ("index.html", INDEX_HTML.to_string()),
        ("viewer.css", STYLE.to_string()),
        ("viewer.js", viewer_js()),
    ]
}
