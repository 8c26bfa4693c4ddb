//! The OBJ loader matches the llvmpipe reference (`oit.py`): the shipped meshes, file order,
//! polygons and relative indices, plain or gzip by content; and it fails with a typed error
//! that says where, never a panic, on truncated or mutated input.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use fragrace::scene::builtin::SplitMix64;
use fragrace::scene::{
    content_hash, load_obj, load_obj_with_hash, parse_obj_bytes, Scene, SceneError,
};
use fragrace_emu::geometry::Mesh;

fn asset(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("assets")
        .join(name)
}

fn gunzip(bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(bytes), &mut out).unwrap();
    out
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    enc.write_all(bytes).unwrap();
    enc.finish().unwrap()
}

fn temp_file(name: &str, bytes: &[u8]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fragrace-scenes-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

fn parse(text: &str) -> Result<Mesh, SceneError> {
    parse_obj_bytes(text.as_bytes())
}

// ------------------------------------------------------------------------------ shipped meshes

#[test]
fn shipped_meshes_match_the_reference_loader() {
    // Vertex and triangle counts and bounding-sphere radii from oit.py's load_obj + normalise.
    for (file, vertices, triangles, radius) in [
        ("bunny.obj.gz", 1839, 3674, 0.670116889075993),
        ("teapot.obj.gz", 792, 992, 0.5193312955440182),
        ("dragon_res4.obj.gz", 5205, 11102, 0.5388322587947597),
    ] {
        let mesh = load_obj(asset(file)).unwrap();
        assert_eq!(
            (mesh.positions.len(), mesh.triangle_count()),
            (vertices, triangles),
            "{file}"
        );
        let scene = Scene::from_obj(asset(file)).unwrap();
        assert!(
            (f64::from(scene.radius) - radius).abs() < 1e-6,
            "{file}: radius {} vs {radius}",
            scene.radius
        );
    }
    assert_eq!(
        Scene::builtin("bunny").unwrap().mesh,
        Scene::from_obj(asset("bunny.obj.gz")).unwrap().mesh
    );
    assert_eq!(Scene::builtin("teapot").unwrap().mesh.triangle_count(), 992);
}

#[test]
fn obj_keeps_file_order_like_the_reference() {
    // The first bunny vertex and triangle, as in the file (oit.py keeps file order).
    let mesh = load_obj(asset("bunny.obj.gz")).unwrap();
    assert_eq!(mesh.positions[0].to_array(), [1.3019, 0.122622, 2.55006]);
    let text = String::from_utf8(gunzip(&std::fs::read(asset("bunny.obj.gz")).unwrap())).unwrap();
    let first_face: Vec<u32> = text
        .lines()
        .find(|l| l.starts_with("f "))
        .unwrap()
        .split_whitespace()
        .skip(1)
        .map(|s| s.parse::<u32>().unwrap() - 1)
        .collect();
    assert_eq!(mesh.indices[0].to_vec(), first_face);
}

#[test]
fn content_hash_is_sha256_of_the_raw_bytes() {
    assert_eq!(
        content_hash(b"abc"),
        "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
    );
    let bytes = std::fs::read(asset("teapot.obj.gz")).unwrap();
    let (_, hash) = load_obj_with_hash(asset("teapot.obj.gz")).unwrap();
    assert_eq!(hash, content_hash(&bytes));
}

// ------------------------------------------------------------------------------ OBJ forms

#[test]
fn obj_face_forms_polygons_and_relative_indices() {
    let v = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 1.5 0\nvt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\n";
    let tris = |body: &str| parse(&format!("{v}{body}")).unwrap().indices;
    assert_eq!(tris("f 1 2 3\n"), vec![[0, 1, 2]]);
    assert_eq!(tris("f 1/1/1 2/2/1 3/3/1\n"), vec![[0, 1, 2]]);
    assert_eq!(tris("f 1//1 2//1 3//1\n"), vec![[0, 1, 2]]);
    assert_eq!(tris("f 1/1 2/2 3/3\n"), vec![[0, 1, 2]]);
    // Relative indices: -1 is the last vertex defined so far.
    assert_eq!(
        tris("f -5 -4 -3\nf -1/-1/-1 -2/-2/-1 -3/-3/-1\n"),
        vec![[0, 1, 2], [4, 3, 2]]
    );
    // Polygons as fans (v0, vi, vi+1), as oit.py triangulates them.
    assert_eq!(tris("f 1 2 3 4 5\n"), vec![[0, 1, 2], [0, 2, 3], [0, 3, 4]]);
    assert_eq!(tris("f 1 2 3 4\n"), vec![[0, 1, 2], [0, 2, 3]]);
    // Points and lines are not surfaces; groups, materials, comments are ignored.
    assert_eq!(
        tris("o a\ng b\nusemtl m\nmtllib x.mtl\ns 1\n# c\nl 1 2 3\nf 1 2\nf 3\nf 1 2 3\n"),
        vec![[0, 1, 2]]
    );
    // Unreferenced vertices are kept (they count in the bounds, as in oit.py).
    assert_eq!(parse(&format!("{v}f 1 2 3\n")).unwrap().positions.len(), 5);
    // Forward references are allowed (tobj and oit.py allow them).
    assert_eq!(
        parse("f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n")
            .unwrap()
            .indices,
        vec![[0, 1, 2]]
    );
    // CRLF, BOM, w, vertex colours.
    let m = parse("\u{feff}v 0 0 0\r\nv 2 0 0 2\r\nv 0 1 0 0.5 0.5 0.5\r\nf 1 2 3\r\n").unwrap();
    assert_eq!(m.positions[1].x, 1.0);
    assert_eq!(m.positions.len(), 3);
}

#[test]
fn obj_plain_and_gzip_are_detected_by_content() {
    let text = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    let plain = parse_obj_bytes(text).unwrap();
    assert_eq!(parse_obj_bytes(&gzip(text)).unwrap(), plain);
    // A gzip file without .gz, a plain file without .obj.
    assert_eq!(
        load_obj(temp_file("model.bin", &gzip(text))).unwrap(),
        plain
    );
    assert_eq!(load_obj(temp_file("model.txt", text)).unwrap(), plain);
    // Concatenated gzip members (what `cat a.gz b.gz` gives) are one stream.
    let mut two = gzip(b"v 0 0 0\nv 1 0 0\n");
    two.extend(gzip(b"v 0 1 0\nf 1 2 3\n"));
    assert_eq!(parse_obj_bytes(&two).unwrap(), plain);
}

// ------------------------------------------------------------------------------ OBJ errors

#[test]
fn obj_errors_are_typed_and_say_where() {
    let missing = Path::new("/nonexistent/dir/model.obj");
    let err = load_obj(missing).unwrap_err();
    assert!(matches!(err, SceneError::NotFound { .. }), "{err}");
    assert!(err.to_string().contains("model.obj"), "{err}");

    let err = load_obj(temp_file("plain.obj.gz", b"v 0 0 0\n")).unwrap_err();
    assert!(matches!(err, SceneError::NotGzip { .. }), "{err}");

    let gz = std::fs::read(asset("teapot.obj.gz")).unwrap();
    for cut in [3, 10, gz.len() / 2, gz.len() - 4] {
        let err = parse_obj_bytes(&gz[..cut]).unwrap_err();
        assert!(
            matches!(err, SceneError::CorruptGzip { .. }),
            "cut {cut}: {err}"
        );
    }
    let mut flipped = gz.clone();
    flipped[gz.len() / 2] ^= 0x55;
    assert!(matches!(
        parse_obj_bytes(&flipped),
        Err(SceneError::CorruptGzip { .. })
    ));

    let err = parse("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n").unwrap_err();
    assert!(
        matches!(
            err,
            SceneError::NonFiniteVertex {
                line: 2,
                vertex: 2,
                ..
            }
        ),
        "{err}"
    );
    for bad in ["v inf 0 0", "v 0 1e39 0", "v 1 2 3 1e-45"] {
        let err = parse(&format!("v 0 0 0\n{bad}\nv 0 1 0\nf 1 2 3\n")).unwrap_err();
        assert!(
            matches!(err, SceneError::NonFiniteVertex { line: 2, .. }),
            "{bad}: {err}"
        );
    }

    let err = parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99\n").unwrap_err();
    assert!(
        matches!(
            err,
            SceneError::FaceIndexOutOfRange {
                line: 4,
                index: 99,
                vertices: 3,
                ..
            }
        ),
        "{err}"
    );
    assert!(
        err.to_string().contains(":4:") && err.to_string().contains("99"),
        "{err}"
    );
    for (bad, index) in [
        ("f 0 1 2", 0),
        ("f 1 2 -4", -4),
        ("f 1 2 -99999999999999", -99999999999999),
        ("f 1 2 4294967296", 4294967296),
    ] {
        let err = parse(&format!("v 0 0 0\nv 1 0 0\nv 0 1 0\n{bad}\n")).unwrap_err();
        assert!(
            matches!(err, SceneError::FaceIndexOutOfRange { index: i, .. } if i == index),
            "{bad}: {err}"
        );
    }
    // A relative index counts only the vertices defined before its line.
    let err = parse("v 0 0 0\nv 1 0 0\nf -1 -2 -3\nv 0 1 0\n").unwrap_err();
    assert!(
        matches!(
            err,
            SceneError::FaceIndexOutOfRange {
                line: 3,
                index: -3,
                vertices: 2,
                ..
            }
        ),
        "{err}"
    );

    for (bad, line) in [
        ("v 0 0\n", 1),
        ("v 0 0 0\nv 0 x 0\n", 2),
        ("v 0 0 0 1 1\n", 1),
        ("v 0 0 0 0\n", 1),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 three\n", 4),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/x 2 3\n", 4),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1/1/1 2 3\n", 4),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf /1 2 3\n", 4),
    ] {
        let err = parse(bad).unwrap_err();
        assert!(
            matches!(err, SceneError::MalformedObj { line: l, .. } if l == line),
            "{bad:?}: {err}"
        );
    }

    for empty in [
        "",
        "# nothing\n",
        "v 0 0 0\nv 1 0 0\n",
        "v 0 0 0\nv 1 0 0\nf 1 2\n",
    ] {
        assert!(
            matches!(parse(empty), Err(SceneError::EmptyMesh { .. })),
            "{empty:?}"
        );
    }
    // A mesh whose vertices all coincide cannot be framed.
    assert!(matches!(
        Scene::from_mesh("dot", parse("v 1 1 1\nf 1 1 1\n").unwrap()),
        Err(SceneError::DegenerateMesh { .. })
    ));
}

#[test]
fn obj_never_panics_on_truncated_or_mutated_input() {
    let text = gunzip(&std::fs::read(asset("teapot.obj.gz")).unwrap());
    // Truncated anywhere (mid-number, mid-line): a mesh or an error, never a panic.
    for cut in (0..text.len())
        .step_by(97)
        .chain(text.len() - 200..text.len())
    {
        let _ = parse_obj_bytes(&text[..cut]);
    }
    let mut rng = SplitMix64::new(99);
    // Garbage.
    for len in [1, 2, 10, 100, 1000, 10_000] {
        let bytes: Vec<u8> = (0..len).map(|_| rng.next_u64() as u8).collect();
        assert!(parse_obj_bytes(&bytes).is_err());
        let mut gz = vec![0x1f, 0x8b];
        gz.extend(&bytes);
        assert!(parse_obj_bytes(&gz).is_err());
    }
    // OBJ-shaped garbage: random lines of keywords and numbers.
    let words = [
        "v",
        "f",
        "vt",
        "vn",
        "o",
        "g",
        "l",
        "#",
        "1",
        "-1",
        "0",
        "2/3",
        "1//2",
        "-9223372036854775808",
        "nan",
        "1e40",
        "/",
        "//",
        "\u{feff}",
        "é",
        "\t",
    ];
    for _ in 0..3000 {
        let mut s = String::new();
        for _ in 0..rng.below(12) {
            s.push_str(words[rng.below(words.len() as u64) as usize]);
            s.push(if rng.below(4) == 0 { '\n' } else { ' ' });
        }
        let _ = parse(&s);
    }
    // Byte mutations of a real file.
    let small = &text[..text.len().min(4000)];
    for _ in 0..2000 {
        let mut bytes = small.to_vec();
        for _ in 0..1 + rng.below(8) {
            let i = rng.below(bytes.len() as u64) as usize;
            bytes[i] = rng.next_u64() as u8;
        }
        let _ = parse_obj_bytes(&bytes);
    }
}
