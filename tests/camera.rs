//! The camera reproduces `oit.py`'s matrices, frames the bounding sphere, and gives
//! primitive colours as the peer does.

use fragrace::scene::{camera_rig, prim_color, prim_color_rgba8, Camera, Scene, SceneError};
use glam::{DMat4, DVec3, DVec4, Mat4};

// ------------------------------------------------------------------------------ camera

/// Row-major matrices printed by `oit.camera(...)[0]` (numpy, float64).
type Rows = [[f64; 4]; 4];

/// `oit.camera`'s arguments (radius, azimuth, elevation, width, height, fovy, fill).
type CameraArgs = (f64, f64, f64, u32, u32, f64, f64);

/// (arguments, matrix, (distance, near, far)).
fn reference_cameras() -> Vec<(CameraArgs, Rows, (f64, f64, f64))> {
    vec![
        (
            (0.8660254037844386, 0.0, 0.0, 512, 512, 60.0, 0.8),
            [
                [1.7320508075688774, 0.0, 0.0, 0.0],
                [0.0, 1.7320508075688774, 0.0, 0.0],
                [0.0, 0.0, -2.339064861882205, 0.8664218974218656],
                [0.0, 0.0, -1.0, 2.065338955232288],
            ],
            (2.065338955232288, 1.187320415933371, 2.960678002606894),
        ),
        (
            (0.75, 30.0, 20.0, 640, 480, 60.0, 0.8),
            [
                [
                    1.1250000000000002,
                    0.0,
                    -0.649519052838329,
                    3.925816070913635e-17,
                ],
                [
                    -0.2961981327260238,
                    1.6275953626987476,
                    -0.5130302149885032,
                    -1.2793773677544738e-17,
                ],
                [
                    -1.0990009951251591,
                    -0.8000072993089875,
                    -1.9035255611255322,
                    0.7503433735624516,
                ],
                [
                    -0.46984631039295416,
                    -0.3420201433256687,
                    -0.8137976813493738,
                    1.7886360026567734,
                ],
            ],
            (1.7886360026567731, 1.0282496426302055, 2.5640223626833407),
        ),
        (
            // Near the pole: the `up` special case.
            (1.2, -135.0, 89.95, 300, 500, 45.0, 0.6),
            [
                [
                    -2.8451779686442458,
                    0.0,
                    2.845177968644246,
                    4.439459362288698e-19,
                ],
                [
                    1.70710613116851,
                    0.0021067985080824568,
                    1.7071061311685098,
                    3.087969886760181e-18,
                ],
                [
                    0.003924008892520823,
                    -6.359127000976474,
                    0.003924008892520823,
                    1.2050540145686668,
                ],
                [
                    0.0006170669964236504,
                    -0.9999996192282494,
                    0.0006170669964236503,
                    8.136356763691522,
                ],
            ],
            (8.136356763691522, 6.866993196054606, 9.429720331328436),
        ),
        (
            (0.7, 210.0, -60.0, 256, 256, 60.0, 0.8),
            [
                [-1.5, 0.0, 0.8660254037844389, 4.285680677843548e-17],
                [
                    -0.7500000000000002,
                    0.8660254037844389,
                    -1.2990381056766578,
                    -1.9751352901951005e-16,
                ],
                [
                    0.5847662154705515,
                    2.0256895914895288,
                    1.0128447957447646,
                    0.7003204819916204,
                ],
                [
                    0.2500000000000001,
                    0.8660254037844386,
                    0.4330127018922194,
                    1.6693936024796547,
                ],
            ],
            (1.6693936024796547, 0.9596996664548583, 2.393087538504451),
        ),
    ]
}

#[test]
fn camera_matches_oit_py() {
    for ((radius, az, el, w, h, fovy, fill), rows, (distance, near, far)) in reference_cameras() {
        let rig = camera_rig(radius, az, el, w, h, fovy, fill);
        let want = DMat4::from_cols_array_2d(&rows).transpose();
        let diff = (rig.view_proj - want)
            .to_cols_array()
            .iter()
            .fold(0.0f64, |m, d| m.max(d.abs()));
        assert!(
            diff < 1e-12,
            "camera {az} {el}: max diff {diff}\n{:?}",
            rig.view_proj
        );
        assert!(
            (rig.distance - distance).abs() < 1e-12
                && (rig.near - near).abs() < 1e-12
                && (rig.far - far).abs() < 1e-12
        );
        // The f32 matrix is the f64 one rounded, column-major.
        let m32 = fragrace::scene::camera(radius, az, el, w, h, fovy, fill);
        assert_eq!(m32, rig.view_proj.as_mat4());
        assert_eq!(m32.row(3).z, rows[3][2] as f32);
        assert_eq!(m32.row(0).x, rows[0][0] as f32);
        // Through Camera (f32 fields).
        let cam = Camera {
            azimuth: az as f32,
            elevation: el as f32,
            fovy: fovy as f32,
            fill: fill as f32,
            ..Camera::default()
        };
        let vp = cam.view_proj(radius as f32, w, h);
        let diff = (vp - want.as_mat4())
            .to_cols_array()
            .iter()
            .fold(0.0f32, |m, d| m.max(d.abs()));
        assert!(diff < 1e-5, "Camera {cam:?}: {diff}");
    }
}

#[test]
fn camera_frames_the_bounding_sphere() {
    // The eye is on +Z at azimuth 0, on +X at 90; the origin projects to the centre; the
    // bounding sphere's silhouette spans `fill` of the smaller dimension.
    let r = 0.8f64;
    for (az, axis) in [(0.0, DVec3::Z), (90.0, DVec3::X)] {
        let rig = camera_rig(r, az, 0.0, 400, 300, 60.0, 0.8);
        assert!((rig.eye.normalize() - axis).length() < 1e-12);
        let o = rig.view_proj * DVec4::W;
        assert!(o.x.abs() < 1e-12 && o.y.abs() < 1e-12);
        let z = -1.0 + 2.0 * (rig.distance - r) / rig.distance; // inside the near..far range
        assert!(z.is_finite());
        // A point on the silhouette, straight up from the centre as seen from the eye.
        let f = -rig.eye.normalize();
        let up = DVec3::Y;
        let tangent_angle = (r / rig.distance).asin();
        let dir = f * tangent_angle.cos() + up * tangent_angle.sin();
        let p = rig.eye + dir * (rig.distance * tangent_angle.cos());
        let clip = rig.view_proj * p.extend(1.0);
        assert!((clip.y / clip.w - 0.8).abs() < 1e-9, "{}", clip.y / clip.w);
        assert!(clip.z / clip.w > -1.0 && clip.z / clip.w < 1.0);
    }
}

#[test]
fn camera_defaults_and_serde() {
    let cam = Camera::default();
    assert_eq!(
        (cam.azimuth, cam.elevation, cam.fovy, cam.fill),
        (0.0, 0.0, 60.0, 0.8)
    );
    let json = serde_json::to_string(&Camera::new(30.0, 20.0)).unwrap();
    assert_eq!(
        serde_json::from_str::<Camera>(&json).unwrap(),
        Camera::new(30.0, 20.0)
    );
    // Omitted fields take the defaults, so case files can be terse.
    assert_eq!(
        serde_json::from_str::<Camera>(r#"{"azimuth": 45}"#).unwrap(),
        Camera::new(45.0, 0.0)
    );
    // f32 fields widen through their decimal form: fill 0.8 is oit.py's 0.8 exactly.
    let from_f32 = Camera::new(30.0, 20.0).rig(0.75, 640, 480).view_proj;
    let from_f64 = camera_rig(0.75, 30.0, 20.0, 640, 480, 60.0, 0.8).view_proj;
    assert_eq!(from_f32, from_f64);
    // Cameras that cannot frame anything are refused, not turned into NaN matrices.
    assert!(Camera::default().validate(512, 512).is_ok());
    assert!(Camera {
        fill: 2.0,
        ..Camera::default()
    }
    .validate(64, 32)
    .is_ok());
    for (cam, w, h) in [
        (
            Camera {
                fovy: 0.0,
                ..Camera::default()
            },
            8,
            8,
        ),
        (
            Camera {
                fovy: 180.0,
                ..Camera::default()
            },
            8,
            8,
        ),
        (
            Camera {
                fill: 0.0,
                ..Camera::default()
            },
            8,
            8,
        ),
        (
            Camera {
                fill: f32::INFINITY,
                ..Camera::default()
            },
            8,
            8,
        ),
        (
            Camera {
                azimuth: f32::NAN,
                ..Camera::default()
            },
            8,
            8,
        ),
        (Camera::default(), 0, 8),
    ] {
        assert!(
            matches!(cam.validate(w, h), Err(SceneError::BadCamera { .. })),
            "{cam:?} {w}x{h}"
        );
    }
    // Scene::view_proj is the camera's with the scene's radius.
    let scene = Scene::builtin("cubes").unwrap();
    let vp: Mat4 = scene.view_proj(&Camera::default(), 512, 512);
    assert_eq!(vp, Camera::default().view_proj(scene.radius, 512, 512));
}

#[test]
fn prim_color_matches_oit_py() {
    // hash32 and the packed RGBA8 values computed by the reference's formula in numpy.
    for (id, rgb, packed) in [
        (
            0u32,
            [
                0.20000000298023224,
                0.20000000298023224,
                0.20000000298023224,
            ],
            0xff333333u32,
        ),
        (
            1,
            [0.8023529648780823, 0.6517647504806519, 0.6298039555549622],
            0xffa1a6cd,
        ),
        (
            2,
            [0.6047059297561646, 0.30352941155433655, 0.25960785150527954],
            0xff424d9a,
        ),
        (
            12345,
            [0.9749019742012024, 0.9905882477760315, 0.34431374073028564],
            0xff58fdf9,
        ),
        (
            u32::MAX,
            [0.43215686082839966, 0.6078431606292725, 0.5262745022773743],
            0xff869b6e,
        ),
    ] {
        let c = prim_color(id);
        assert_eq!(
            [c[0], c[1], c[2], c[3]],
            [rgb[0] as f32, rgb[1] as f32, rgb[2] as f32, 1.0],
            "{id}"
        );
        assert_eq!(prim_color_rgba8(id), packed, "{id}");
    }
}
