//! OBJ faces that tobj refuses without saying where, or reads wrongly, are refused with their
//! line; faces it reads rightly (forward references, relative indices, mixed UVs) still read.

use plenoptic_io::{Error, read_mesh};

/// Four vertices of a unit square (lines 1–4), two UVs (lines 5–6), then `faces`.
fn obj(faces: &str) -> String {
    format!("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 1\n{faces}")
}

fn read(text: &str) -> Result<plenoptic_io::Mesh, Error> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.obj");
    std::fs::write(&path, text).unwrap();
    read_mesh(&path)
}

#[test]
fn bad_faces_are_refused_naming_their_line() {
    for (faces, expected) in [
        (
            "f 1 2 3\nf 0 1 2\n",
            "line 8: f: '0': v index 0 (OBJ indices count from 1)",
        ),
        (
            "f 1 2 9\n",
            "line 7: f: '9': v index 9, but the file has 4 v lines",
        ),
        (
            "f -5 1 2\n",
            "line 7: f: '-5': v index -5, before the first (only 4 v lines precede it)",
        ),
        // tobj ignored these two: no vn lines at all, and a vt past the two there are.
        (
            "f 1//3 2//3 3//3\n",
            "line 7: f: '1//3': vn index 3, but the file has 0 vn lines",
        ),
        (
            "f 1/1 2/2 3/3\n",
            "line 7: f: '3/3': vt index 3, but the file has 2 vt lines",
        ),
        ("f 1 2\n", "line 7: f: 2 vertices; a face needs at least 3"),
        ("f\n", "line 7: f: 0 vertices; a face needs at least 3"),
        (
            "f 1/1/1/1 2 3\n",
            "line 7: f: '1/1/1/1' is not a vertex (v, v/vt, v//vn or v/vt/vn)",
        ),
        ("f /1 2 3\n", "line 7: f: '/1' is not a vertex"),
        ("f 1 x2 3\n", "line 7: f: 'x2' in 'x2' is not a v index"),
        (
            "mtllib missing.mtl\nusemtl red paint\nf 1 2 3\n",
            "line 8: usemtl 'red paint', but the material library cannot be read",
        ),
        // tobj said "position parse error" (or normal, texture) without a line.
        (
            "v 0 0\nf 1 2 3\n",
            "line 7: v: 2 number(s); it needs at least 3 (x, y, z)",
        ),
        ("v 0 zero 0\n", "line 7: v: 'zero' is not a number"),
        ("vn 0 1\n", "line 7: vn: 2 number(s); it needs at least 3"),
        ("vt\n", "line 7: vt: 0 number(s); it needs at least 1 (u)"),
    ] {
        let e = read(&obj(faces)).unwrap_err();
        let message = e.to_string();
        assert!(
            matches!(e, Error::Obj { .. }) && message.contains(expected),
            "{faces:?}: {message}"
        );
    }
}

#[test]
fn good_faces_still_read() {
    // Relative indices, and a face before the vertices it names.
    let mesh = read(&obj("f -4 -3 -2\nf 1 3 4\n")).unwrap();
    assert_eq!(mesh.triangles.len(), 2);
    let forward = read("f 1 2 3\nv 0 0 0\nv 1 0 0\nv 1 1 0\n").unwrap();
    assert_eq!(forward.triangles.len(), 1);
    // A missing library with no usemtl is no error.
    let mesh = read(&obj("mtllib missing.mtl\nf 1 2 3\n")).unwrap();
    assert_eq!(mesh.triangles.len(), 1);
    // Faces with UVs and a face without: tobj gives the latter's vertices no UV, so the UVs
    // would pair with the wrong vertices; they are dropped instead.
    let mixed = read(&obj("f 1/1 2/2 3/2\nf 1 3 4\n")).unwrap();
    assert_eq!(mixed.triangles.len(), 2);
    assert!(mixed.uvs.is_none(), "{:?}", mixed.uvs);
    let with_uvs = read(&obj("f 1/1 2/2 3/2\n")).unwrap();
    assert_eq!(
        with_uvs.uvs.as_ref().map(Vec::len),
        Some(with_uvs.positions.len())
    );
}
