//! The thin-lens camera of DESIGN §2 against hand-computed numbers, the
//! camera file, and the defaults (auto-framing, automatic aperture).

mod common;

use glam::{Vec2, Vec3};
use pointlens::camera::{self, Camera, CameraSpec, Coordinates};
use pointlens::Error;

fn close(a: f32, b: f32, tol: f32) -> bool {
    (a - b).abs() <= tol
}

#[track_caller]
fn assert_close(actual: f32, expected: f32, tol: f32) {
    assert!(
        close(actual, expected, tol),
        "{actual} != {expected} (± {tol})"
    );
}

#[track_caller]
fn assert_close2(actual: Vec2, expected: Vec2, tol: f32) {
    assert!(
        (actual - expected).abs().max_element() <= tol,
        "{actual} != {expected} (± {tol})"
    );
}

/// 640 × 480, 40°, at the origin looking down −z.
fn axis_camera() -> Camera {
    common::camera(640, 480)
}

/// H = 100 and θ = 90° give f_px = 50 / tan(45°) = 50; R = 0.1, S = 2.
fn lens_camera() -> Camera {
    Camera {
        width: 200,
        height: 100,
        eye: Vec3::ZERO,
        target: Vec3::new(0.0, 0.0, -1.0),
        up: Vec3::Y,
        fovy_deg: 90.0,
        aperture_radius: 0.1,
        focus_distance: 2.0,
        aperture: pointlens::camera::Aperture::ROUND,
    }
}

/// The error's one-line text, asserting it is a camera error naming `field`.
#[track_caller]
fn camera_error(result: pointlens::Result<impl std::fmt::Debug>, field: &str) -> String {
    let err = result.expect_err("expected an error");
    let text = err.to_string();
    match &err {
        Error::Camera { field: f, .. } => assert_eq!(*f, field, "{text}"),
        other => panic!("expected a camera error naming {field}, got {other:?}"),
    }
    assert!(
        text.contains(field),
        "error text does not name {field}: {text}"
    );
    text
}

/// A complete camera file (every required field) to take single fields out of.
fn complete() -> CameraSpec {
    CameraSpec {
        width: Some(64),
        height: Some(48),
        eye: Some([0.0, 0.0, 5.0]),
        target: Some([0.0, 0.0, 0.0]),
        fovy_deg: Some(40.0),
        aperture_radius: Some(0.05),
        focus_distance: Some(5.0),
        ..CameraSpec::default()
    }
}

fn resolve(spec: &CameraSpec) -> pointlens::Result<Camera> {
    let points = [Vec3::splat(-1.0), Vec3::splat(1.0)];
    camera::resolve(spec, Vec3::splat(-1.0), Vec3::splat(1.0), &points)
}

// ---------------------------------------------------------------- projection

#[test]
fn f_px_for_480_pixels_and_40_degrees() {
    // f_px = (480 / 2) / tan(40° / 2) = 240 / 0.36397023 = 659.3946
    assert_close(axis_camera().f_px(), 659.3946, 1e-3);
}

#[test]
fn basis_of_the_axis_camera() {
    // forward = (0, 0, −1); right = (0, 0, −1) × (0, 1, 0) = (1, 0, 0);
    // up' = (1, 0, 0) × (0, 0, −1) = (0, 1, 0).
    let (right, up, forward) = axis_camera().basis();
    assert_eq!(right, Vec3::X);
    assert_eq!(up, Vec3::Y);
    assert_eq!(forward, -Vec3::Z);
}

#[test]
fn projection_of_the_axis_camera() {
    let cam = axis_camera();
    // f_px = 659.3946 (above).
    // (0, 0, −5): z = 5, on the axis → the image centre (320, 240).
    let (p, z) = cam.project(Vec3::new(0.0, 0.0, -5.0)).unwrap();
    assert_close2(p, Vec2::new(320.0, 240.0), 1e-4);
    assert_close(z, 5.0, 1e-6);
    // (1, 0.5, −2): z = 2; x = 320 + 659.3946 · 1/2 = 649.6973;
    //               y = 240 − 659.3946 · 0.5/2 = 240 − 164.8486 = 75.1514.
    let (p, z) = cam.project(Vec3::new(1.0, 0.5, -2.0)).unwrap();
    assert_close2(p, Vec2::new(649.6973, 75.1514), 1e-3);
    assert_close(z, 2.0, 1e-6);
    // (−2, −1, −10): z = 10; x = 320 − 659.3946 · 0.2 = 188.1211;
    //                y = 240 + 659.3946 · 0.1 = 305.9395.
    let (p, z) = cam.project(Vec3::new(-2.0, -1.0, -10.0)).unwrap();
    assert_close2(p, Vec2::new(188.1211, 305.9395), 1e-3);
    assert_close(z, 10.0, 1e-6);
    // Eye space is z > 0 in front (not glam's −z view space).
    assert_eq!(
        cam.eye_from_world(Vec3::new(1.0, 0.5, -2.0)),
        Vec3::new(1.0, 0.5, 2.0)
    );
    // Behind the eye, or in its plane: no projection.
    assert!(cam.project(Vec3::new(0.0, 0.0, 1.0)).is_none());
    assert!(cam.project(Vec3::new(1.0, 1.0, 0.0)).is_none());
}

/// eye (2, 2, 1), target 0, up +y, 200 × 100, θ = 90° (f_px = 50).
fn oblique_camera() -> Camera {
    Camera {
        width: 200,
        height: 100,
        eye: Vec3::new(2.0, 2.0, 1.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fovy_deg: 90.0,
        aperture_radius: 0.0,
        focus_distance: 3.0,
        aperture: pointlens::camera::Aperture::ROUND,
    }
}

#[test]
fn projection_of_an_oblique_camera() {
    let cam = oblique_camera();
    let s5 = 5f32.sqrt();
    // |target − eye| = |(−2, −2, −1)| = 3 → forward = (−2, −2, −1)/3;
    // forward × (0, 1, 0) = (−fz, 0, fx) = (1/3, 0, −2/3), length √5/3
    //   → right = (1, 0, −2)/√5;
    // up' = right × forward = (−4/(3√5), 5/(3√5), −2/(3√5)) = (−4, 5, −2)/(3√5).
    let (right, up, forward) = cam.basis();
    assert!((right - Vec3::new(1.0, 0.0, -2.0) / s5).length() < 1e-6);
    assert!((up - Vec3::new(-4.0, 5.0, -2.0) / (3.0 * s5)).length() < 1e-6);
    assert!((forward - Vec3::new(-2.0, -2.0, -1.0) / 3.0).length() < 1e-6);
    assert_close(cam.f_px(), 50.0, 1e-4); // 50 / tan(45°)

    // The target: z = 3, the image centre (100, 50).
    let (p, z) = cam.project(Vec3::ZERO).unwrap();
    assert_close2(p, Vec2::new(100.0, 50.0), 1e-4);
    assert_close(z, 3.0, 1e-5);

    // P = (0, 1, 0): d = P − eye = (−2, −1, −1);
    //   x = d·right = (−2 + 2)/√5 = 0; y = d·up' = (8 − 5 + 2)/(3√5) = √5/3;
    //   z = d·forward = (4 + 2 + 1)/3 = 7/3;
    //   x_px = 100 + 0 = 100; y_px = 50 − 50 · (√5/3)/(7/3) = 50 − 50√5/7
    //        = 50 − 15.97191 = 34.02809.
    let (p, z) = cam.project(Vec3::Y).unwrap();
    assert_close2(p, Vec2::new(100.0, 34.02809), 1e-3);
    assert_close(z, 7.0 / 3.0, 1e-5);

    // Q = (1, 0, 0): d = (−1, −2, −1);
    //   x = (−1 + 2)/√5 = 1/√5; y = (4 − 10 + 2)/(3√5) = −4/(3√5); z = (2 + 4 + 1)/3 = 7/3;
    //   x_px = 100 + 50 · (1/√5)/(7/3) = 100 + 150/(7√5) = 100 + 9.58315 = 109.58315;
    //   y_px = 50 + 50 · (4/(3√5))/(7/3) = 50 + 200/(7√5) = 50 + 12.77753 = 62.77753.
    let (p, z) = cam.project(Vec3::X).unwrap();
    assert_close2(p, Vec2::new(109.58315, 62.77753), 1e-3);
    assert_close(z, 7.0 / 3.0, 1e-5);
}

#[test]
fn eye_from_world_transform_is_bitwise_eye_from_world() {
    // A fixed xorshift sequence: 25 cameras × 16 points, coordinates in
    // [−scale, scale) with scales from 0.01 to 1000.
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move |scale: f32| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        ((state >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0) * scale
    };
    let mut vec3 = |scale: f32| Vec3::new(next(scale), next(scale), next(scale));
    let bits = |v: Vec3| v.to_array().map(f32::to_bits);
    let mut compared = 0;
    for c in 0..25 {
        let scale = [0.01, 1.0, 10.0, 1000.0][c % 4];
        let cam = Camera {
            eye: vec3(scale),
            target: vec3(scale),
            up: vec3(1.0),
            ..oblique_camera()
        };
        let (right, up, forward) = cam.basis();
        if !(right.is_finite() && up.is_finite() && forward.is_finite()) {
            continue;
        }
        let transform = cam.eye_from_world_transform();
        for i in 0..16 {
            let p = vec3([0.01, 1.0, 100.0, 1000.0][i % 4]);
            assert_eq!(
                bits(transform.apply(p)),
                bits(cam.eye_from_world(p)),
                "camera {cam:?}, point {p}"
            );
            compared += 1;
        }
    }
    assert!(compared >= 300, "only {compared} points compared");
}

// ---------------------------------------------------------------- the lens

#[test]
fn circle_of_confusion() {
    let cam = lens_camera();
    // c(z) = 2R · f_px · |z − S| / (z · S) = 2 · 0.1 · 50 · |z − 2| / (2z) = 5 |z − 2| / z.
    assert_eq!(cam.coc_px(2.0), 0.0); // z = S
    assert_close(cam.coc_px(4.0), 2.5, 1e-5); // z = 2S: 5 · 2 / 4
    assert_close(cam.coc_px(1.0), 5.0, 1e-5); // z = S/2: 5 · 1 / 1
                                              // z = ∞: the background, 2R · f_px / S = 2 · 0.1 · 50 / 2 = 5 (no NaN).
    assert_close(cam.coc_px(f32::INFINITY), 5.0, 1e-5);
    // The largest CoC over a depth range is at one of its ends.
    assert_close(cam.max_coc_px(1.0, 4.0), 5.0, 1e-5); // max(5, 2.5)
                                                       // c(1.5) = 5 · 0.5 / 1.5 = 1.6667, c(6) = 5 · 4 / 6 = 3.3333.
    assert_close(cam.max_coc_px(1.5, 6.0), 10.0 / 3.0, 1e-5);
    assert_close(cam.max_coc_px(1.5, f32::INFINITY), 5.0, 1e-5);
    // A pinhole blurs nothing, background included.
    let pinhole = Camera {
        aperture_radius: 0.0,
        ..cam
    };
    assert_eq!(pinhole.coc_px(0.5), 0.0);
    assert_eq!(pinhole.coc_px(f32::INFINITY), 0.0);
}

#[test]
fn lens_sign_and_offset() {
    let cam = lens_camera();
    assert_eq!(cam.lens_sign(4.0), 1.0); // behind the focus plane
    assert_eq!(cam.lens_sign(f32::INFINITY), 1.0);
    assert_eq!(cam.lens_sign(1.0), -1.0); // in front of it
    let u = Vec2::new(1.0, 0.0);
    // far: +1 · (2.5 / 2) · u = (1.25, 0); near: −1 · (5 / 2) · u = (−2.5, 0).
    assert_close2(cam.lens_offset_px(4.0, u), Vec2::new(1.25, 0.0), 1e-5);
    assert_close2(cam.lens_offset_px(1.0, u), Vec2::new(-2.5, 0.0), 1e-5);
    // u = (0.6, −0.8): far (1.25 · 0.6, 1.25 · −0.8) = (0.75, −1.0).
    let u = Vec2::new(0.6, -0.8);
    assert_close2(cam.lens_offset_px(4.0, u), Vec2::new(0.75, -1.0), 1e-5);
    // background: +1 · (5 / 2) · u = (1.5, −2.0).
    assert_close2(
        cam.lens_offset_px(f32::INFINITY, u),
        Vec2::new(1.5, -2.0),
        1e-5,
    );
}

#[test]
fn near_and_far_points_move_in_opposite_directions_and_the_focus_plane_stays() {
    let cam = lens_camera();
    for u in [
        Vec2::new(1.0, 0.0),
        Vec2::new(0.0, -1.0),
        Vec2::new(-0.3, 0.4),
    ] {
        let near = cam.lens_offset_px(1.0, u);
        let far = cam.lens_offset_px(4.0, u);
        assert!(near.dot(u) < 0.0, "near point moves against u: {near}");
        assert!(far.dot(u) > 0.0, "far point moves with u: {far}");
        assert!(near.dot(far) < 0.0, "opposite directions: {near} vs {far}");
        assert_eq!(
            cam.lens_offset_px(2.0, u),
            Vec2::ZERO,
            "a point at S is not displaced"
        );
    }
}

#[test]
fn lens_offset_is_the_thin_lens_ray_geometry() {
    // Physical check of the sheared projection: the ray from the lens point
    // L = eye + R (u.x · right − u.y · up') (u in pixel axes, y down) through P
    // crosses the focus plane (depth S) at F; every ray through F reaches
    // F's pinhole image, so P is seen there: project(F) = project(P) + offset.
    let cam = Camera {
        eye: Vec3::new(0.5, 1.0, 3.0),
        target: Vec3::new(0.0, 0.2, -1.0),
        aperture_radius: 0.2,
        focus_distance: 3.0,
        ..oblique_camera()
    };
    let (right, up, _) = cam.basis();
    for p in [
        Vec3::new(0.3, 0.1, -4.0),
        Vec3::new(-0.2, 0.5, 1.5),
        Vec3::new(0.0, 0.0, -0.5),
    ] {
        let (pinhole, z) = cam.project(p).unwrap();
        for u in [
            Vec2::new(1.0, 0.0),
            Vec2::new(0.0, 1.0),
            Vec2::new(-0.6, 0.7),
        ] {
            let lens = cam.eye + cam.aperture_radius * (u.x * right - u.y * up);
            let f = lens + (p - lens) * (cam.focus_distance / z);
            let (seen, _) = cam.project(f).unwrap();
            assert_close2(seen, pinhole + cam.lens_offset_px(z, u), 2e-3);
        }
    }
}

#[test]
fn guard_band() {
    let cam = Camera {
        width: 64,
        height: 48,
        ..oblique_camera()
    };
    // ⌈max CoC / 2 + max splat / 2⌉
    assert_eq!(cam.guard_band_px(5.0, 3.0), 4); // ⌈2.5 + 1.5⌉ = 4
    assert_eq!(cam.guard_band_px(4.2, 1.0), 3); // ⌈2.1 + 0.5⌉ = ⌈2.6⌉ = 3
    assert_eq!(cam.guard_band_px(0.0, 1.0), 1); // ⌈0.5⌉ = 1
    assert_eq!(cam.guard_band_px(0.0, 0.0), 0);
    // Bounded by half the larger side, whatever the blur (a point at the
    // lens has an infinite CoC).
    assert_eq!(cam.max_guard_px(), 32);
    assert_eq!(cam.guard_band_px(62.0, 1.0), 32); // ⌈31 + 0.5⌉ = 32
    assert_eq!(cam.guard_band_px(61.0, 1.0), 31);
    assert_eq!(cam.guard_band_px(1e9, 0.0), 32);
    assert_eq!(cam.guard_band_px(f32::INFINITY, 1.0), 32);
    assert_eq!(cam.guard_band_px(f32::NAN, 1.0), 32);
    let odd = Camera {
        width: 33,
        height: 65,
        ..cam
    };
    assert_eq!(odd.max_guard_px(), 33);
    // A CoC above twice the bound is the veil's (crate::veil).
    assert_eq!(cam.veil_coc_px(), 64.0);
}

// ---------------------------------------------------------------- camera file

#[test]
fn camera_file_parses_every_field_and_ignores_unknown_ones() {
    let json = r#"{
        "width": 800, "height": 600,
        "eye": [1.0, 2.0, 3.0], "target": [0, 0.5, -1], "up": [0, 0, 1],
        "fovy_deg": 35.5, "focal_length_mm": 50, "sensor_height_mm": 24,
        "aperture_radius": 0.25, "f_number": 2.8, "units_per_mm": 0.001,
        "focus_distance": 4.5,
        "comment": "unknown fields are ignored", "lens": {"make": "x", "n": [1, 2]}
    }"#;
    let spec = CameraSpec::from_json_str(json).unwrap();
    assert_eq!(
        spec,
        CameraSpec {
            coordinates: None,
            origin: None,
            width: Some(800),
            height: Some(600),
            eye: Some([1.0, 2.0, 3.0]),
            target: Some([0.0, 0.5, -1.0]),
            up: Some([0.0, 0.0, 1.0]),
            fovy_deg: Some(35.5),
            focal_length_mm: Some(50.0),
            sensor_height_mm: Some(24.0),
            sensor_width_mm: None,
            aperture_radius: Some(0.25),
            f_number: Some(2.8),
            units_per_mm: Some(0.001),
            focus_distance: Some(4.5),
            aperture: Default::default(),
        }
    );
    spec.require_complete().unwrap();
    // Every field is used as given: fovy_deg wins over the focal length,
    // aperture_radius over f_number.
    let cam = resolve(&spec).unwrap();
    assert_eq!(
        cam,
        Camera {
            width: 800,
            height: 600,
            eye: Vec3::new(1.0, 2.0, 3.0),
            target: Vec3::new(0.0, 0.5, -1.0),
            up: Vec3::Z,
            fovy_deg: 35.5,
            aperture_radius: 0.25,
            focus_distance: 4.5,
            aperture: pointlens::camera::Aperture::ROUND,
        }
    );
    // An empty file is a valid (incomplete) spec.
    assert_eq!(
        CameraSpec::from_json_str("{}").unwrap(),
        CameraSpec::default()
    );
}

#[test]
fn camera_file_from_disk_and_its_errors() {
    let dir = common::scratch("camera-file");
    let path = dir.join("cam.json");
    std::fs::write(&path, r#"{"width": 32, "focus_distance": 2}"#).unwrap();
    let spec = CameraSpec::from_json_file(&path).unwrap();
    assert_eq!((spec.width, spec.focus_distance), (Some(32), Some(2.0)));

    // Not JSON: Error::Json naming the file, with serde's line and column.
    std::fs::write(&path, "{\n  \"width\": 32,\n  oops\n}").unwrap();
    let err = CameraSpec::from_json_file(&path).unwrap_err();
    assert!(matches!(err, Error::Json { .. }), "{err:?}");
    let text = err.to_string();
    assert!(
        text.contains("cam.json") && text.contains("line 3") && text.contains("column"),
        "{text}"
    );

    // A wrong type: Error::Json too, saying what was expected where.
    std::fs::write(&path, r#"{"width": "wide"}"#).unwrap();
    let err = CameraSpec::from_json_file(&path).unwrap_err();
    let text = err.to_string();
    assert!(matches!(err, Error::Json { .. }), "{err:?}");
    assert!(
        text.contains("invalid type") && text.contains("line 1"),
        "{text}"
    );
    let err = CameraSpec::from_json_str(r#"{"eye": [1, 2]}"#).unwrap_err();
    assert!(
        matches!(err, Error::Json { .. }) && err.to_string().contains("column"),
        "{err}"
    );

    // Unreadable: Error::Io naming the file.
    let missing = dir.join("missing.json");
    let err = CameraSpec::from_json_file(&missing).unwrap_err();
    assert!(matches!(err, Error::Io { .. }), "{err:?}");
    assert!(err.to_string().contains("missing.json"), "{err}");
}

#[test]
fn flags_override_single_fields() {
    let file = CameraSpec {
        f_number: Some(4.0),
        focal_length_mm: Some(35.0),
        ..complete()
    };
    let flags = CameraSpec {
        width: Some(320),
        focus_distance: Some(7.5),
        eye: Some([1.0, 1.0, 1.0]),
        ..CameraSpec::default()
    };
    let spec = file.clone().overridden_by(&flags);
    assert_eq!(
        spec,
        CameraSpec {
            width: Some(320),
            focus_distance: Some(7.5),
            eye: Some([1.0, 1.0, 1.0]),
            ..file.clone()
        }
    );
    // No flags: the file unchanged. Every field can be overridden.
    assert_eq!(file.clone().overridden_by(&CameraSpec::default()), file);
    let all = CameraSpec {
        coordinates: Some(Coordinates::File),
        origin: Some([13.0; 3]),
        width: Some(1),
        height: Some(2),
        eye: Some([3.0; 3]),
        target: Some([4.0; 3]),
        up: Some([5.0; 3]),
        fovy_deg: Some(6.0),
        focal_length_mm: Some(7.0),
        sensor_height_mm: Some(8.0),
        sensor_width_mm: Some(14.0),
        aperture_radius: Some(9.0),
        f_number: Some(10.0),
        units_per_mm: Some(11.0),
        focus_distance: Some(12.0),
        aperture: pointlens::camera::ApertureSpec {
            aperture_blades: Some(5),
            aperture_rotation_deg: Some(15.0),
            blade_curvature: Some(0.25),
            anamorphic_ratio: Some(1.5),
            aperture_image: Some("star.png".into()),
            cat_eye: Some(0.5),
        },
    };
    assert_eq!(file.overridden_by(&all), all);
}

#[test]
fn an_incomplete_camera_file_names_the_first_missing_field() {
    complete().require_complete().unwrap();
    let cases = [
        (
            "width",
            CameraSpec {
                width: None,
                ..complete()
            },
        ),
        (
            "height",
            CameraSpec {
                height: None,
                ..complete()
            },
        ),
        (
            "eye",
            CameraSpec {
                eye: None,
                ..complete()
            },
        ),
        (
            "target",
            CameraSpec {
                target: None,
                ..complete()
            },
        ),
        (
            "fovy_deg",
            CameraSpec {
                fovy_deg: None,
                ..complete()
            },
        ),
        (
            "focus_distance",
            CameraSpec {
                focus_distance: None,
                ..complete()
            },
        ),
    ];
    for (field, spec) in cases {
        camera_error(spec.require_complete(), field);
    }
    // The first missing one is named.
    let spec = CameraSpec {
        height: None,
        focus_distance: None,
        ..complete()
    };
    camera_error(spec.require_complete(), "height");
    // No aperture at all.
    let spec = CameraSpec {
        aperture_radius: None,
        ..complete()
    };
    let text = camera_error(spec.require_complete(), "aperture_radius");
    assert!(text.contains("f_number"), "{text}");
    // The field of view from half a focal length/sensor pair.
    let spec = CameraSpec {
        fovy_deg: None,
        focal_length_mm: Some(50.0),
        ..complete()
    };
    camera_error(spec.require_complete(), "sensor_height_mm");
    let spec = CameraSpec {
        fovy_deg: None,
        sensor_height_mm: Some(24.0),
        ..complete()
    };
    camera_error(spec.require_complete(), "focal_length_mm");
    // Alternatives are complete: focal length + sensor; f_number; no up.
    CameraSpec {
        fovy_deg: None,
        focal_length_mm: Some(50.0),
        sensor_height_mm: Some(24.0),
        aperture_radius: None,
        f_number: Some(2.0),
        ..complete()
    }
    .require_complete()
    .unwrap();
}

// ---------------------------------------------------------------- resolution

#[test]
fn focal_length_gives_the_field_of_view() {
    let spec = CameraSpec {
        fovy_deg: None,
        focal_length_mm: Some(50.0),
        sensor_height_mm: Some(24.0),
        ..complete()
    };
    // θ = 2 · atan(24 / (2 · 50)) = 2 · atan(0.24) = 2 · 13.49573° = 26.99147°
    assert_close(resolve(&spec).unwrap().fovy_deg, 26.99147, 1e-3);
    // fovy_deg wins when both are given.
    let spec = CameraSpec {
        fovy_deg: Some(60.0),
        ..spec
    };
    assert_eq!(resolve(&spec).unwrap().fovy_deg, 60.0);
}

#[test]
fn a_sensor_width_is_fitted_to_the_image_width() {
    let spec = CameraSpec {
        fovy_deg: None,
        width: Some(640),
        height: Some(480),
        focal_length_mm: Some(50.0),
        sensor_width_mm: Some(36.0),
        ..complete()
    };
    // The sensor's 36 mm span the 640 pixels: the height sees 36·480/640 =
    // 27 mm, θ = 2·atan(27 / 100) = 30.21915°.
    assert_close(resolve(&spec).unwrap().fovy_deg, 30.21915, 1e-3);
    // A portrait image: the width still spans the sensor's width.
    let portrait = CameraSpec {
        width: Some(480),
        height: Some(640),
        ..spec.clone()
    };
    let expected = (2.0 * (36.0f64 * 640.0 / 480.0 / 100.0).atan()).to_degrees();
    assert_close(resolve(&portrait).unwrap().fovy_deg, expected as f32, 1e-3);
    // The sensor height gives the same camera where it is the width's share.
    let by_height = CameraSpec {
        sensor_width_mm: None,
        sensor_height_mm: Some(27.0),
        ..spec.clone()
    };
    assert_close(
        resolve(&by_height).unwrap().fovy_deg,
        resolve(&spec).unwrap().fovy_deg,
        1e-5,
    );
    // Both sizes: an error naming the field (which side would they fit?).
    let both = CameraSpec {
        sensor_height_mm: Some(24.0),
        ..spec.clone()
    };
    camera_error(resolve(&both), "sensor_width_mm");
    // A sensor width is a field of view for the completeness check.
    CameraSpec {
        fovy_deg: None,
        sensor_height_mm: None,
        ..spec
    }
    .require_complete()
    .unwrap();
    camera_error(
        resolve(&CameraSpec {
            sensor_width_mm: Some(-1.0),
            ..complete()
        }),
        "sensor_width_mm",
    );
}

#[test]
fn f_number_gives_the_aperture_and_aperture_radius_wins() {
    let spec = CameraSpec {
        aperture_radius: None,
        f_number: Some(2.0),
        focal_length_mm: Some(50.0),
        units_per_mm: Some(0.001),
        ..complete()
    };
    // f = 50 mm · 0.001 units/mm = 0.05; R = f / 2N = 0.05 / 4 = 0.0125.
    assert_close(resolve(&spec).unwrap().aperture_radius, 0.0125, 1e-7);
    // With fovy_deg given, the focal length only sets the aperture.
    assert_eq!(resolve(&spec).unwrap().fovy_deg, 40.0);
    let spec = CameraSpec {
        aperture_radius: Some(0.3),
        ..spec
    };
    assert_eq!(resolve(&spec).unwrap().aperture_radius, 0.3);
}

#[test]
fn f_number_needs_a_focal_length_in_scene_units() {
    let spec = CameraSpec {
        aperture_radius: None,
        f_number: Some(2.0),
        ..complete()
    };
    let text = camera_error(resolve(&spec), "focal_length_mm");
    assert!(
        text.contains("f_number needs focal_length_mm and units_per_mm"),
        "{text}"
    );
    let spec = CameraSpec {
        focal_length_mm: Some(50.0),
        ..spec
    };
    camera_error(resolve(&spec), "units_per_mm");
    let spec = CameraSpec {
        focal_length_mm: None,
        units_per_mm: Some(0.001),
        ..spec
    };
    camera_error(resolve(&spec), "focal_length_mm");
}

#[test]
fn half_a_focal_length_pair_is_an_error() {
    let spec = CameraSpec {
        fovy_deg: None,
        focal_length_mm: Some(50.0),
        ..complete()
    };
    camera_error(resolve(&spec), "sensor_height_mm");
    let spec = CameraSpec {
        fovy_deg: None,
        sensor_height_mm: Some(24.0),
        ..complete()
    };
    camera_error(resolve(&spec), "focal_length_mm");
}

#[test]
fn impossible_values_name_their_field() {
    let nan = f32::NAN;
    let inf = f32::INFINITY;
    let cases: Vec<(&str, CameraSpec)> = vec![
        (
            "width",
            CameraSpec {
                width: Some(0),
                ..complete()
            },
        ),
        (
            "height",
            CameraSpec {
                height: Some(0),
                ..complete()
            },
        ),
        (
            "fovy_deg",
            CameraSpec {
                fovy_deg: Some(0.0),
                ..complete()
            },
        ),
        (
            "fovy_deg",
            CameraSpec {
                fovy_deg: Some(180.0),
                ..complete()
            },
        ),
        (
            "fovy_deg",
            CameraSpec {
                fovy_deg: Some(-10.0),
                ..complete()
            },
        ),
        (
            "fovy_deg",
            CameraSpec {
                fovy_deg: Some(nan),
                ..complete()
            },
        ),
        (
            "focus_distance",
            CameraSpec {
                focus_distance: Some(0.0),
                ..complete()
            },
        ),
        (
            "focus_distance",
            CameraSpec {
                focus_distance: Some(-1.0),
                ..complete()
            },
        ),
        (
            "focus_distance",
            CameraSpec {
                focus_distance: Some(nan),
                ..complete()
            },
        ),
        (
            "focus_distance",
            CameraSpec {
                focus_distance: Some(inf),
                ..complete()
            },
        ),
        (
            "aperture_radius",
            CameraSpec {
                aperture_radius: Some(-0.1),
                ..complete()
            },
        ),
        (
            "aperture_radius",
            CameraSpec {
                aperture_radius: Some(inf),
                ..complete()
            },
        ),
        (
            "aperture_radius",
            CameraSpec {
                aperture_radius: Some(nan),
                ..complete()
            },
        ),
        (
            "f_number",
            CameraSpec {
                f_number: Some(0.0),
                ..complete()
            },
        ),
        (
            "f_number",
            CameraSpec {
                f_number: Some(-2.0),
                ..complete()
            },
        ),
        (
            "focal_length_mm",
            CameraSpec {
                focal_length_mm: Some(0.0),
                ..complete()
            },
        ),
        (
            "sensor_height_mm",
            CameraSpec {
                sensor_height_mm: Some(-1.0),
                ..complete()
            },
        ),
        (
            "units_per_mm",
            CameraSpec {
                units_per_mm: Some(0.0),
                ..complete()
            },
        ),
        (
            "eye",
            CameraSpec {
                eye: Some([0.0, f64::from(nan), 1.0]),
                ..complete()
            },
        ),
        (
            "target",
            CameraSpec {
                target: Some([f64::from(inf), 0.0, 0.0]),
                ..complete()
            },
        ),
        (
            "up",
            CameraSpec {
                up: Some([0.0, nan, 0.0]),
                ..complete()
            },
        ),
        (
            "up",
            CameraSpec {
                up: Some([0.0, 0.0, 0.0]),
                ..complete()
            },
        ),
        // Degenerate poses: the eye at the target, or on the line target ± up.
        (
            "eye",
            CameraSpec {
                eye: Some([0.0, 0.0, 0.0]),
                ..complete()
            },
        ),
        (
            "up",
            CameraSpec {
                eye: Some([0.0, 3.0, 0.0]),
                ..complete()
            },
        ),
        (
            "up",
            CameraSpec {
                eye: Some([0.0, -2.0, 0.0]),
                ..complete()
            },
        ),
        (
            "up",
            CameraSpec {
                up: Some([0.0, 0.0, -1.0]),
                ..complete()
            },
        ),
    ];
    for (field, spec) in cases {
        camera_error(resolve(&spec), field);
    }
    // An empty cloud has no centre to look at, nor anything to frame.
    let empty = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    camera_error(
        camera::resolve(&CameraSpec::default(), empty.0, empty.1, &[]),
        "target",
    );
    let spec = CameraSpec {
        target: Some([0.0; 3]),
        ..CameraSpec::default()
    };
    camera_error(camera::resolve(&spec, empty.0, empty.1, &[]), "eye");
    // Auto-framing looks along −z, so an up of ±z cannot orient it.
    let spec = CameraSpec {
        up: Some([0.0, 0.0, 2.0]),
        ..CameraSpec::default()
    };
    camera_error(resolve(&spec), "up");
    // Just inside the limits is fine.
    resolve(&CameraSpec {
        fovy_deg: Some(179.0),
        aperture_radius: Some(0.0),
        ..complete()
    })
    .unwrap();
    resolve(&CameraSpec {
        width: Some(1),
        height: Some(1),
        ..complete()
    })
    .unwrap();
}

#[test]
fn defaults_without_a_camera() {
    let points = [Vec3::new(-1.0, -1.0, -1.0), Vec3::new(3.0, 1.0, 1.0)];
    let cam = camera::resolve(&CameraSpec::default(), points[0], points[1], &points).unwrap();
    assert_eq!(
        (cam.width, cam.height, cam.fovy_deg, cam.up),
        (640, 480, 40.0, Vec3::Y)
    );
    // Target: the bounding-box centre (1, 0, 0); eye straight down +z from it.
    assert_eq!(cam.target, Vec3::new(1.0, 0.0, 0.0));
    assert_eq!((cam.eye.x, cam.eye.y), (1.0, 0.0));
    assert!(cam.eye.z > 1.0);
    // Focus: the eye depth of the target.
    assert_close(cam.focus_distance, cam.eye.z, 1e-5);
    assert!(cam.aperture_radius > 0.0);
}

#[test]
fn eye_without_target_looks_at_the_centre_and_focuses_there() {
    let spec = CameraSpec {
        eye: Some([3.0, 4.0, 2.0]),
        ..CameraSpec::default()
    };
    let cam = camera::resolve(
        &spec,
        Vec3::new(-1.0, 0.0, 0.0),
        Vec3::new(1.0, 4.0, 4.0),
        &[],
    )
    .unwrap();
    // centre = (0, 2, 2); |target − eye| = |(−3, −2, 0)| = √13 = 3.60555.
    assert_eq!(cam.target, Vec3::new(0.0, 2.0, 2.0));
    assert_eq!(cam.eye, Vec3::new(3.0, 4.0, 2.0));
    assert_close(cam.focus_distance, 3.60555, 1e-4);
}

#[test]
fn auto_framing_by_hand() {
    // 100 × 100, θ = 90°: f_px = 50. Points (±1, 0, 0) around the target 0;
    // a 5 % margin leaves 45 px from the centre to the edge, so each point
    // needs z ≥ f_px · |x| / 45 = 50/45 = 10/9: eye = (0, 0, 10/9).
    let points = [Vec3::new(-1.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0)];
    let spec = CameraSpec {
        width: Some(100),
        height: Some(100),
        fovy_deg: Some(90.0),
        ..CameraSpec::default()
    };
    let cam = camera::resolve(&spec, points[0], points[1], &points).unwrap();
    assert!(
        (cam.eye - Vec3::new(0.0, 0.0, 10.0 / 9.0)).length() < 1e-5,
        "{}",
        cam.eye
    );
    // x_px = 50 ± 50 · 1 / (10/9) = 50 ± 45: at 5 and 95, the 5 % margin.
    assert_close(cam.project(points[0]).unwrap().0.x, 5.0, 1e-3);
    assert_close(cam.project(points[1]).unwrap().0.x, 95.0, 1e-3);
    assert_close(cam.focus_distance, 10.0 / 9.0, 1e-5);
    // Every point at the focus depth: no CoC to aim for, so the fallback
    // R = 0.01 × bounding-box diagonal = 0.01 × 2 = 0.02.
    assert_close(cam.aperture_radius, 0.02, 1e-6);

    // A wide image: the vertical extent limits. 200 × 100 with points
    // (0, ±1, 0): 45 px vertically → d = 50/45 again; horizontally 90 px
    // would allow less.
    let points = [Vec3::new(0.0, -1.0, 0.0), Vec3::new(0.0, 1.0, 0.0)];
    let spec = CameraSpec {
        width: Some(200),
        ..spec
    };
    let cam = camera::resolve(&spec, points[0], points[1], &points).unwrap();
    assert_close(cam.eye.z, 10.0 / 9.0, 1e-5);
}

#[test]
fn automatic_aperture_by_hand() {
    // 100 × 100, θ = 90° (f_px = 50); points (±1, 0, 0), (0, 0, ±1), centre 0.
    // Framing: (±1, 0, 0) need d = 50/45 = 10/9; (0, 0, 1) needs d ≥ 1 + a
    // hair; (0, 0, −1) nothing. Eye (0, 0, 10/9), S = 10/9.
    // Depths: near 10/9 − 1 = 1/9, far 10/9 + 1 = 19/9.
    // CoC per unit R: 2 · 50 · |z − S| / (z S):
    //   z = 1/9:  100 · (9/9) / ((1/9)(10/9)) = 100 · 81/10  = 810;
    //   z = 19/9: 100 · (9/9) / ((19/9)(10/9)) = 100 · 81/190 = 42.63.
    // Goal max(4, 100/60) = 4 px → R = 4 / 810 = 0.00493827.
    let points = [
        Vec3::new(-1.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.0, 0.0, 1.0),
        Vec3::new(0.0, 0.0, -1.0),
    ];
    let spec = CameraSpec {
        width: Some(100),
        height: Some(100),
        fovy_deg: Some(90.0),
        ..CameraSpec::default()
    };
    let (lo, hi) = (Vec3::new(-1.0, 0.0, -1.0), Vec3::new(1.0, 0.0, 1.0));
    let cam = camera::resolve(&spec, lo, hi, &points).unwrap();
    assert!(
        (cam.eye - Vec3::new(0.0, 0.0, 10.0 / 9.0)).length() < 1e-5,
        "{}",
        cam.eye
    );
    assert_close(cam.focus_distance, 10.0 / 9.0, 1e-5);
    assert_close(cam.aperture_radius, 4.0 / 810.0, 1e-7);
    // The front is blurred by exactly the goal.
    assert_close(cam.coc_px(1.0 / 9.0), 4.0, 1e-3);

    // At 480 × 480 the framing is the same (d = 240/216 = 10/9), the goal is
    // max(4, 480/60) = 8 px and f_px = 240 = 4.8 × 50, so the CoC per unit R
    // at z = 1/9 is 810 · 4.8 = 3888 and R = 8 / 3888 = 0.00205761.
    let spec = CameraSpec {
        width: Some(480),
        height: Some(480),
        ..spec
    };
    let cam = camera::resolve(&spec, lo, hi, &points).unwrap();
    assert_close(cam.aperture_radius, 8.0 / (810.0 * 4.8), 1e-7);

    // The focus distance given: the goal is met at the worse end.
    let spec = CameraSpec {
        focus_distance: Some(19.0 / 9.0),
        ..spec
    };
    let cam = camera::resolve(&spec, lo, hi, &points).unwrap();
    let worst = cam.coc_px(1.0 / 9.0).max(cam.coc_px(19.0 / 9.0));
    assert_close(worst, 8.0, 1e-3);
}

/// A deterministic test cloud: a tilted, off-centre, elongated blob.
fn test_cloud() -> Vec<Vec3> {
    let mut state = 12345u32;
    let mut next = move || {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (state >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
    };
    (0..500)
        .map(|_| {
            let (a, b, c) = (next(), next(), next());
            Vec3::new(10.0 + 3.0 * a + b, -4.0 + 1.5 * b, 2.0 + 2.5 * c - a)
        })
        .collect()
}

fn bounds(points: &[Vec3]) -> (Vec3, Vec3) {
    points.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    )
}

#[test]
fn auto_framing_fills_the_view() {
    let points = test_cloud();
    let (lo, hi) = bounds(&points);
    for (w, h) in [(640, 480), (480, 640), (100, 100), (1000, 200)] {
        let spec = CameraSpec {
            width: Some(w),
            height: Some(h),
            ..CameraSpec::default()
        };
        let cam = camera::resolve(&spec, lo, hi, &points).unwrap();
        let (wf, hf) = (w as f32, h as f32);
        // Looking along −z at the box centre.
        assert_eq!(cam.target, (lo + hi) / 2.0);
        assert_eq!((cam.eye.x, cam.eye.y), (cam.target.x, cam.target.y));
        assert!((cam.basis().2 + Vec3::Z).length() < 1e-6);
        let mut closest_to_edge = f32::INFINITY;
        for p in &points {
            let (q, z) = cam.project(*p).expect("every point in front of the eye");
            assert!(z > 0.0);
            // Inside the image with the 5 % margin (a rounding hair of slack).
            assert!(
                q.x >= 0.05 * wf - 1e-2 && q.x <= 0.95 * wf + 1e-2,
                "{w}×{h}: {p} at {q}"
            );
            assert!(
                q.y >= 0.05 * hf - 1e-2 && q.y <= 0.95 * hf + 1e-2,
                "{w}×{h}: {p} at {q}"
            );
            let edge = (q.x / wf)
                .min(1.0 - q.x / wf)
                .min(q.y / hf)
                .min(1.0 - q.y / hf);
            closest_to_edge = closest_to_edge.min(edge);
        }
        // And it fills the view: some point is within 6 % of an edge.
        assert!(
            closest_to_edge <= 0.06,
            "{w}×{h}: nearest edge {closest_to_edge}"
        );
        // The automatic aperture blurs front or back by max(4, H/60) px.
        let depths: Vec<f32> = points.iter().map(|p| cam.eye_from_world(*p).z).collect();
        let near = depths.iter().copied().fold(f32::INFINITY, f32::min);
        let far = depths.iter().copied().fold(0.0, f32::max);
        assert_close(cam.max_coc_px(near, far), (hf / 60.0).max(4.0), 1e-2);
    }
}

#[test]
fn auto_framing_without_points_frames_the_box() {
    let (lo, hi) = (Vec3::new(-2.0, -1.0, -1.0), Vec3::new(2.0, 1.0, 1.0));
    let cam = camera::resolve(&CameraSpec::default(), lo, hi, &[]).unwrap();
    for i in 0..8 {
        let corner = Vec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        );
        let (q, _) = cam.project(corner).unwrap();
        assert!(
            q.x >= 31.99 && q.x <= 608.01 && q.y >= 23.99 && q.y <= 456.01,
            "{corner} at {q}"
        );
    }
}

// ---------------------------------------------------------------- round trip

#[test]
fn print_camera_round_trips() {
    let points = test_cloud();
    let (lo, hi) = bounds(&points);
    let auto = camera::resolve(&CameraSpec::default(), lo, hi, &points).unwrap();
    let oblique = Camera {
        eye: Vec3::new(0.1, 2.0 / 3.0, 1e-3),
        target: Vec3::new(-7.25, 0.3, 1.0 / 7.0),
        up: Vec3::new(0.1, 0.9, 0.2),
        fovy_deg: 33.3333,
        aperture_radius: 0.012_345_678,
        focus_distance: 9.87654,
        ..oblique_camera()
    };
    for cam in [auto, oblique, axis_camera()] {
        let json = cam.to_json();
        let spec = CameraSpec::from_json_str(&json).unwrap();
        spec.require_complete().unwrap();
        // Only the resolved fields are written.
        assert_eq!(spec, cam.to_spec());
        assert!(
            spec.f_number.is_none() && spec.focal_length_mm.is_none(),
            "{json}"
        );
        // Resolving it again, against any cloud, gives the same camera.
        let again = camera::resolve(&spec, Vec3::ZERO, Vec3::ONE, &[]).unwrap();
        assert_eq!(again, cam, "{json}");
    }
    let json = axis_camera().to_json();
    for key in [
        "width",
        "height",
        "eye",
        "target",
        "up",
        "fovy_deg",
        "aperture_radius",
        "focus_distance",
    ] {
        assert!(
            json.contains(&format!("\"{key}\"")),
            "{key} missing from {json}"
        );
    }
}

#[test]
fn concentric_map_is_area_preserving_and_inside_the_disk() {
    use pointlens::camera::{concentric_disk, lens_samples};
    // Corners and edge midpoints of the square land on the unit circle.
    for a in [
        Vec2::new(1.0, 0.0),
        Vec2::new(0.0, 1.0),
        Vec2::new(-1.0, 0.0),
        Vec2::new(1.0, 1.0),
    ] {
        assert!((concentric_disk(a).length() - 1.0).abs() < 1e-6, "{a}");
    }
    assert_eq!(concentric_disk(Vec2::ZERO), Vec2::ZERO);
    // (1, 0) maps to angle 0; (1, 1) to 45°; (0, 1) to 90°.
    assert!((concentric_disk(Vec2::new(1.0, 1.0)) - Vec2::splat(0.5f32.sqrt())).length() < 1e-6);
    assert!((concentric_disk(Vec2::new(0.0, 1.0)) - Vec2::Y).length() < 1e-6);
    // Area preservation: the inner half-size square [−½, ½]² (a quarter of
    // the area) maps onto the disk of radius ½ (a quarter of the area).
    assert!((concentric_disk(Vec2::new(0.5, 0.2)).length() - 0.5).abs() < 1e-6);
    // Lens samples: inside the disk, centred, and spread evenly: a quarter
    // of them within radius ½ (equal area), within one sample.
    let s = lens_samples(256);
    assert!(s.iter().all(|u| u.length() <= 1.0 + 1e-6));
    let mean = s.iter().copied().sum::<Vec2>() / 256.0;
    assert!(mean.length() < 0.02, "mean {mean}");
    let inner = s.iter().filter(|u| u.length() < 0.5).count();
    assert!(
        (63..=65).contains(&inner),
        "{inner} of 256 within radius 1/2"
    );
    assert_eq!(lens_samples(1), vec![Vec2::ZERO]);
}

/// The pixel offsets of accum at K = 1: in [−½, ½)², the first at the
/// pixel's centre, and even along each axis for every count, so that an
/// edge through the pixel at any place covers the share of the offsets it
/// covers of the pixel (within 3/S for S ≥ 16: a Kronecker sequence's
/// discrepancy; 2/S fails at 16),
/// and the lens positions do not all land on one side of it.
#[test]
fn pixel_jitters_cover_the_pixel_evenly() {
    use pointlens::camera::pixel_jitters;
    assert_eq!(pixel_jitters(1), vec![Vec2::ZERO]);
    for count in [16u32, 64, 256] {
        let j = pixel_jitters(count);
        assert_eq!(j.len(), count as usize);
        assert!(j
            .iter()
            .all(|o| (-0.5..0.5).contains(&o.x) && (-0.5..0.5).contains(&o.y)));
        for step in 0..=20 {
            let edge = -0.5 + step as f32 / 20.0;
            for axis in [0, 1] {
                let below = j.iter().filter(|o| o[axis] < edge).count() as f32;
                let share = below / count as f32;
                assert!(
                    (share - (edge + 0.5)).abs() <= 3.0 / count as f32,
                    "{count} offsets: {share} below {edge} along axis {axis}"
                );
            }
        }
    }
}

#[test]
fn rdb_bins_round_trip_through_the_concentric_map() {
    use pointlens::camera::{concentric_disk, concentric_square, rdb_bin, rdb_lens_table};
    for n in [2, 5, 9, 16] {
        let table = rdb_lens_table(n);
        assert_eq!(table.len(), (n * n) as usize);
        for (b, u) in table.iter().enumerate() {
            assert_eq!(
                rdb_bin(*u, n),
                b as u32,
                "N = {n}: bin {b}'s centre {u} maps elsewhere"
            );
        }
    }
    // 5×5: bin 12 is the centre cell, u = 0; bin 0 the (−x, −y) corner cell.
    let t = rdb_lens_table(5);
    assert_eq!(t[12], Vec2::ZERO);
    assert!(t[0].x < 0.0 && t[0].y < 0.0);
    for a in [
        Vec2::new(0.3, -0.7),
        Vec2::new(-0.9, 0.2),
        Vec2::new(0.5, 0.5),
        Vec2::new(-0.1, -0.95),
    ] {
        let back = concentric_square(concentric_disk(a));
        assert!((back - a).length() < 1e-5, "{a} -> {back}");
    }
}

#[test]
fn rdb_lens_cells_are_half_open() {
    use pointlens::camera::{concentric_disk, concentric_square, rdb_bin};
    // DESIGN §5: lens cell i of an N×N buffer is [−1 + 2i/N, −1 + 2(i+1)/N)
    // in square space, so a coordinate on an interior boundary −1 + 2k/N
    // belongs to the upper cell k, −1 to cell 0, and +1 (the closed outer
    // edge) is clamped into cell N − 1.
    //
    // For N = 2 and 16 every boundary is an f32. For N = 5 and 9 no interior
    // one is, so "on the boundary" is the smallest f32 at or above it
    // ((v + 1)·N ≥ 2k, exact in f64 for these v), which is in cell k.
    for n in [2u32, 5, 9, 16] {
        let boundary = |k: u32| {
            let at_or_above = |v: f32| (v as f64 + 1.0) * n as f64 >= 2.0 * k as f64;
            let mut v = -1.0 + 2.0 * k as f32 / n as f32;
            if (v as f64 + 1.0) * n as f64 == 2.0 * k as f64 {
                return v; // exact (the only boundary near 0 is 0 itself)
            }
            while !at_or_above(v) {
                v = v.next_up();
            }
            while at_or_above(v.next_down()) {
                v = v.next_down();
            }
            v
        };
        let centre = |j: u32| -1.0 + (2.0 * j as f32 + 1.0) / n as f32;
        // The lens position u is the concentric map of the square point a;
        // only points that come back bit for bit through concentric_square
        // test the cell rule rather than the map's round-off. On the x axis
        // (y = 0) the map is the identity, so those always qualify.
        let bits = |v: Vec2| v.to_array().map(f32::to_bits);
        let mut qualified = 0;
        let mut check = |a: Vec2, i: u32, j: u32| {
            let u = concentric_disk(a);
            if bits(concentric_square(u)) != bits(a) {
                return false;
            }
            assert_eq!(
                rdb_bin(u, n),
                j * n + i,
                "N = {n}: square point ({}, {}) belongs to cell ({i}, {j})",
                a.x,
                a.y
            );
            qualified += 1;
            true
        };
        let middle = n / 2; // the cell of 0: the centre one, or the upper at a boundary
        for k in 0..=n {
            let x = boundary(k);
            let i = k.min(n - 1);
            assert!(check(Vec2::new(x, 0.0), i, middle), "N = {n}, k = {k}");
            if k > 0 {
                // Just below the boundary: still the lower cell.
                assert!(check(Vec2::new(x - 1e-4, 0.0), k - 1, middle));
            }
            // Boundary in x with y at a cell centre, and the same in y.
            for j in 0..n {
                check(Vec2::new(x, centre(j)), i, j);
                check(Vec2::new(centre(j), x), j, i);
            }
        }
        // The 2N + 1 axis points, and at least N of the others.
        assert!(
            qualified > 3 * n,
            "N = {n}: only {qualified} points round-trip exactly"
        );
    }
}

// ------------------------------------------------------- z-up default view

/// A z-up cloud's default camera (LAS, or a PLY saying so): z up, the eye
/// on the −y side 30° above the target's horizon, every point in view; a
/// given up keeps the view along −z.
#[test]
fn a_z_up_cloud_is_seen_obliquely_with_z_up() {
    // A flat field 100 × 60 units, 2 deep: LiDAR's shape.
    let points: Vec<Vec3> = (0..=10)
        .flat_map(|i| {
            (0..=6).map(move |j| {
                Vec3::new(
                    10.0 * i as f32 - 50.0,
                    10.0 * j as f32 - 30.0,
                    (i + j) as f32 % 3.0 - 1.0,
                )
            })
        })
        .collect();
    let (lo, hi) = (Vec3::new(-50.0, -30.0, -1.0), Vec3::new(50.0, 30.0, 1.0));
    let spec = CameraSpec::default();
    let cam = camera::resolve_for(&spec, lo, hi, &points, true).unwrap();
    assert_eq!(cam.up, Vec3::Z);
    let view = (cam.target - cam.eye).normalize();
    let down = (-view.z).asin().to_degrees();
    assert!((down - camera::Z_UP_VIEW_DOWN_DEG).abs() < 1e-3, "{down}°");
    assert!(view.x.abs() < 1e-6 && view.y > 0.0, "{view}");
    for p in &points {
        let (px, _) = cam.project(*p).unwrap();
        assert!(
            px.x > 0.0 && px.x < cam.width as f32 && px.y > 0.0 && px.y < cam.height as f32,
            "{p} at {px}"
        );
    }
    // Not z-up, or an up given: the view straight down −z of before.
    let plain = camera::resolve(&spec, lo, hi, &points).unwrap();
    assert_eq!(
        camera::resolve_for(&spec, lo, hi, &points, false).unwrap(),
        plain
    );
    assert_eq!(plain.up, Vec3::Y);
    assert!(((plain.target - plain.eye).normalize() + Vec3::Z).length() < 1e-6);
    let given = CameraSpec {
        up: Some([0.0, 1.0, 0.0]),
        ..CameraSpec::default()
    };
    assert_eq!(
        camera::resolve_for(&given, lo, hi, &points, true).unwrap(),
        camera::resolve(&given, lo, hi, &points).unwrap()
    );
    // A given eye straight above: +z cannot orient it, so +y does (a
    // top-down LiDAR view without --up).
    let above = CameraSpec {
        eye: Some([0.0, 0.0, 100.0]),
        target: Some([0.0, 0.0, 0.0]),
        ..CameraSpec::default()
    };
    assert_eq!(
        camera::resolve_for(&above, lo, hi, &points, true)
            .unwrap()
            .up,
        Vec3::Y
    );
    let oblique = CameraSpec {
        eye: Some([0.0, -100.0, 50.0]),
        ..above
    };
    assert_eq!(
        camera::resolve_for(&oblique, lo, hi, &points, true)
            .unwrap()
            .up,
        Vec3::Z
    );
}
