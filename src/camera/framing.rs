//! Auto-framing and [`resolve`]: a [`CameraSpec`] and the cloud's points
//! become a [`Camera`], with the automatic eye (framing every point with a
//! [`FRAMING_MARGIN`]) and the automatic aperture.

use glam::{DVec3, Vec3};

use super::file::{camera_error, resolve_fovy, validate, Coordinates};
use super::{Camera, CameraSpec, DEFAULT_HEIGHT, DEFAULT_WIDTH};
use crate::error::Result;
use crate::input::MAX_COORDINATE;

/// Margin that auto-framing leaves on each side of the image, as a fraction
/// of the image width (left and right) or height (top and bottom).
pub const FRAMING_MARGIN: f32 = 0.05;

/// `v` scaled into single precision's range where its length over- or
/// underflows (an `up` of 1e30 is a direction like any other); otherwise
/// `v` itself, bit for bit.
fn in_range_direction(v: Vec3) -> Vec3 {
    let length = v.length();
    let largest = v.abs().max_element();
    if (length.is_finite() && length > 1e-18) || !(largest.is_finite() && largest > 0.0) {
        v
    } else {
        (v / largest).normalize()
    }
}

/// Whether `up` can orient a camera looking along `forward` (not parallel).
fn up_is_usable(forward: Vec3, up: Vec3) -> bool {
    forward.normalize().cross(up.normalize()).length() > 1e-6
}

/// The points that auto-framing and the automatic aperture look at: the
/// finite ones of `points`, or the bounding-box corners when there are none.
/// Borrows `points` (a cloud may hold a hundred million of them).
fn framing_points(points: &[Vec3], lo: Vec3, hi: Vec3) -> impl Iterator<Item = Vec3> + '_ {
    let corners: Vec<Vec3> = if points.iter().any(|p| p.is_finite()) {
        Vec::new()
    } else {
        (0..8)
            .map(|i| {
                Vec3::new(
                    if i & 1 == 0 { lo.x } else { hi.x },
                    if i & 2 == 0 { lo.y } else { hi.y },
                    if i & 4 == 0 { lo.z } else { hi.z },
                )
            })
            .collect()
    };
    points
        .iter()
        .copied()
        .filter(|p| p.is_finite())
        .chain(corners)
}

/// The auto-framed eye: eye = target + (0, 0, d), looking along −z, with the
/// smallest d > 0 such that every point projects inside the image with a
/// [`FRAMING_MARGIN`] on each side and lies at least `near` in front of the
/// eye. Per point q = p − target with eye-space x = q·right, y = q·up' and
/// depth z = d + q·forward, the condition f_px·|x| / z ≤ (1/2 − margin)·W
/// (and likewise for y and H) gives
/// d ≥ f_px·|x| / ((1/2 − margin)·W) − q·forward.
#[allow(clippy::too_many_arguments)]
fn auto_frame_eye(
    target: Vec3,
    back: Vec3,
    up: Vec3,
    width: u32,
    height: u32,
    fovy_deg: f32,
    points: impl Iterator<Item = Vec3>,
    near: f32,
) -> Vec3 {
    let probe = Camera {
        width,
        height,
        eye: target + back,
        target,
        up,
        fovy_deg,
        aperture_radius: 0.0,
        focus_distance: 1.0,
        aperture: crate::camera::Aperture::ROUND,
    };
    let (right, up, forward) = probe.basis();
    let f = probe.f_px();
    let half_w = (0.5 - FRAMING_MARGIN) * width as f32;
    let half_h = (0.5 - FRAMING_MARGIN) * height as f32;
    let mut d = near;
    for p in points {
        let q = p - target;
        let ahead = q.dot(forward);
        let need = (f * q.dot(right).abs() / half_w)
            .max(f * q.dot(up).abs() / half_h)
            .max(near);
        d = d.max(need - ahead);
    }
    target + d * back
}

/// How far below the horizon the default camera of a z-up cloud looks, in
/// degrees: an oblique view, from the −y side (south, for LiDAR), of the
/// whole cloud.
pub const Z_UP_VIEW_DOWN_DEG: f32 = 30.0;

/// The default view of a cloud: the direction from the target to an
/// automatic eye, and the default up. Along +z with y up, unless the
/// data is z-up: then from the −y side, [`Z_UP_VIEW_DOWN_DEG`] above the
/// horizon, with z up.
fn default_view(z_up: bool) -> (Vec3, Vec3) {
    if z_up {
        let down = Z_UP_VIEW_DOWN_DEG.to_radians();
        (Vec3::new(0.0, -down.cos(), down.sin()), Vec3::Z)
    } else {
        (Vec3::Z, Vec3::Y)
    }
}

/// Resolves a camera spec into a [`Camera`], field by field: the spec's
/// value if present, else the default of DESIGN §2.
///
/// * width × height: 640 × 480.
/// * field of view: `fovy_deg`, else 2·atan(h / 2f) from `focal_length_mm` and
///   `sensor_height_mm` (one without the other is an error naming the missing
///   one), else 40°.
/// * up: +y (+z for a z-up cloud, [`resolve_for`]). target: the centre of
///   the bounding box `cloud_min`..`cloud_max`.
/// * eye: auto-framed — looking along −z at the target from the nearest
///   distance at which every point of `points` (the bounding-box corners if
///   it is empty) projects inside the image with a 5 % margin on each side
///   (and at least 0.1 % of the box diagonal in front of the eye).
/// * aperture: `aperture_radius` wins; else `f_number` N gives R = f / 2N
///   with f = `focal_length_mm` · `units_per_mm` (both required); else the
///   automatic aperture: R such that the larger CoC at the nearest and the
///   farthest eye depth of `points` in front of the eye is max(4, H/60)
///   pixels. If every point is at the focus depth (or none is in front), R
///   falls back to 1 % of the bounding-box diagonal (1 % of S if the box is a
///   single point).
/// * focus distance: the eye depth of the target, (target − eye)·forward.
///
/// Impossible values are [`Error::Camera`] naming the field. The device's
/// maximum image size is checked by the renderer, not here.
///
/// [`Error::Camera`]: crate::error::Error::Camera
pub fn resolve(
    spec: &CameraSpec,
    cloud_min: Vec3,
    cloud_max: Vec3,
    points: &[Vec3],
) -> Result<Camera> {
    resolve_for(spec, cloud_min, cloud_max, points, false)
}

/// [`resolve`] for a cloud that says whether its z axis points up
/// (`PointCloud::z_up`: LAS/LAZ, or a PLY saying so). For a z-up cloud the
/// defaults change: up is +z, and the automatic eye looks at the target
/// from the −y side, [`Z_UP_VIEW_DOWN_DEG`] below the horizon (an oblique
/// view of the whole cloud instead of a view straight down). A given `up`
/// keeps the view of [`resolve`] (along −z).
pub fn resolve_for(
    spec: &CameraSpec,
    cloud_min: Vec3,
    cloud_max: Vec3,
    points: &[Vec3],
    z_up: bool,
) -> Result<Camera> {
    validate(spec)?;
    if spec.coordinates == Some(Coordinates::File) || spec.origin.is_some() {
        return Err(camera_error(
            "coordinates",
            "a camera in file coordinates (or with an origin) needs the cloud's origin: take it through CameraSpec::in_scene first",
        ));
    }
    let width = spec.width.unwrap_or(DEFAULT_WIDTH);
    let height = spec.height.unwrap_or(DEFAULT_HEIGHT);
    let fovy_deg = resolve_fovy(spec, width, height)?;
    let (back, default_up) = default_view(z_up && spec.up.is_none());
    let up = in_range_direction(spec.up.map_or(default_up, Vec3::from_array));

    let diagonal = (cloud_max - cloud_min).length();
    let diagonal = if diagonal.is_finite() { diagonal } else { 0.0 };
    let target = match spec.target {
        Some(t) => DVec3::from_array(t).as_vec3(),
        None => {
            let centre = (cloud_min + cloud_max) / 2.0;
            if !centre.is_finite() {
                return Err(camera_error(
                    "target",
                    "no default: the cloud's bounding box is empty or not finite",
                ));
            }
            centre
        }
    };

    let eye = match spec.eye {
        Some(e) => DVec3::from_array(e).as_vec3(),
        None => {
            if !up_is_usable(-back, up) {
                return Err(camera_error(
                    "up",
                    format!(
                        "{up} is parallel to the auto-framing view direction (−z); give another up or an eye"
                    ),
                ));
            }
            let no_points = !points.iter().any(|p| p.is_finite());
            if no_points && !(cloud_min.is_finite() && cloud_max.is_finite()) {
                return Err(camera_error(
                    "eye",
                    "cannot auto-frame: no points and the cloud's bounding box is empty or not finite",
                ));
            }
            let near = if diagonal > 0.0 { 1e-3 * diagonal } else { 1.0 };
            let pts = framing_points(points, cloud_min, cloud_max);
            auto_frame_eye(target, back, up, width, height, fovy_deg, pts, near)
        }
    };
    check_within_range(spec, target, eye, fovy_deg)?;
    if eye == target {
        return Err(camera_error(
            "eye",
            format!("must differ from the target, both are {eye}"),
        ));
    }
    // A z-up cloud's default up, +z, cannot orient a given eye looking
    // straight down (or up): there the default of other clouds, +y.
    let up = if spec.up.is_none() && z_up && !up_is_usable(target - eye, up) {
        Vec3::Y
    } else {
        up
    };
    if !up_is_usable(target - eye, up) {
        return Err(camera_error(
            "up",
            format!("{up} is parallel to the view direction from eye {eye} to target {target}"),
        ));
    }

    let forward = (target - eye).normalize();
    let focus_distance = spec
        .focus_distance
        .unwrap_or_else(|| (target - eye).dot(forward));

    let mut camera = Camera {
        width,
        height,
        eye,
        target,
        up,
        fovy_deg,
        aperture_radius: 0.0,
        focus_distance,
        aperture: spec.aperture.resolve()?,
    };
    camera.aperture_radius = match (spec.aperture_radius, spec.f_number) {
        (Some(r), _) => r,
        (None, Some(n)) => f_number_aperture(spec, n)?,
        (None, None) => auto_aperture(
            &camera,
            framing_points(points, cloud_min, cloud_max),
            diagonal,
        ),
    };
    Ok(camera)
}

/// Refuses a target or eye (`automatic` where not given) that is not
/// finite or lies beyond ±[`MAX_COORDINATE`]: there the squares of
/// distances overflow f32 and every check after this one would fail for a
/// reason it does not name (an eye at 1e20 used to be "up is parallel to
/// the view direction"). An automatic eye's error names the field of view
/// `fovy_deg` that put it there.
fn check_within_range(spec: &CameraSpec, target: Vec3, eye: Vec3, fovy_deg: f32) -> Result<()> {
    for (name, at, automatic) in [
        ("target", target, spec.target.is_none()),
        ("eye", eye, spec.eye.is_none()),
    ] {
        if !at.is_finite() || at.abs().max_element() > MAX_COORDINATE {
            let why = match (name, automatic) {
                ("eye", true) => format!(
                    ": the automatic eye stands that far to fit the cloud's extent in a \
                     {fovy_deg:e}° field of view; widen it (fovy_deg, or a shorter \
                     focal_length_mm for the sensor), or give an eye"
                ),
                _ => String::new(),
            };
            return Err(camera_error(
                name,
                format!(
                    "{at} is beyond ±{MAX_COORDINATE:e} scene units (the lens maths would \
                     overflow single precision){why}"
                ),
            ));
        }
    }
    Ok(())
}

/// The aperture radius of f-number `n`: R = f / 2N with f =
/// `focal_length_mm` · `units_per_mm`, each required (the error names the
/// missing one).
fn f_number_aperture(spec: &CameraSpec, n: f32) -> Result<f32> {
    let msg = "f_number needs focal_length_mm and units_per_mm";
    let f_mm = spec
        .focal_length_mm
        .ok_or_else(|| camera_error("focal_length_mm", msg))?;
    let units = spec
        .units_per_mm
        .ok_or_else(|| camera_error("units_per_mm", msg))?;
    Ok(f_mm * units / (2.0 * n))
}

/// The automatic aperture radius: R such that the larger CoC at the nearest
/// and farthest eye depth of `points` (those in front of the eye) is
/// max(4, H/60) pixels. The CoC is linear in R, so R = goal / CoC(R = 1).
/// Falls back to 1 % of the box diagonal (or of S) when there is no CoC to
/// aim for (every point at the focus depth, or none in front).
fn auto_aperture(camera: &Camera, points: impl Iterator<Item = Vec3>, diagonal: f32) -> f32 {
    let (_, _, forward) = camera.basis();
    let (mut near, mut far) = (f32::INFINITY, 0.0f32);
    for p in points {
        // The eye depth z of `Camera::eye_from_world`, with the basis hoisted.
        let z = (p - camera.eye).dot(forward);
        if z > 0.0 && z.is_finite() {
            near = near.min(z);
            far = far.max(z);
        }
    }
    let goal = (camera.height as f32 / 60.0).max(4.0);
    let unit = Camera {
        aperture_radius: 1.0,
        ..*camera
    };
    let coc_per_unit = if near <= far {
        unit.max_coc_px(near, far)
    } else {
        0.0
    };
    if coc_per_unit > 0.0 && coc_per_unit.is_finite() {
        goal / coc_per_unit
    } else if diagonal > 0.0 {
        0.01 * diagonal
    } else {
        0.01 * camera.focus_distance
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn framing_points_fall_back_to_the_box_corners() {
        let (lo, hi) = (Vec3::new(-1.0, -2.0, -3.0), Vec3::new(1.0, 2.0, 3.0));
        // Finite points are used as they are, non-finite ones skipped.
        let points = [Vec3::ONE, Vec3::new(f32::NAN, 0.0, 0.0), Vec3::ZERO];
        let used: Vec<Vec3> = framing_points(&points, lo, hi).collect();
        assert_eq!(used, vec![Vec3::ONE, Vec3::ZERO]);
        // No finite point: the 8 corners.
        let corners: Vec<Vec3> = framing_points(&[], lo, hi).collect();
        assert_eq!(corners.len(), 8);
        assert!(corners.contains(&lo) && corners.contains(&hi));
        assert!(corners.contains(&Vec3::new(1.0, -2.0, 3.0)));
    }

    #[test]
    fn up_parallel_to_the_view_is_unusable() {
        assert!(up_is_usable(-Vec3::Z, Vec3::Y));
        assert!(up_is_usable(-Vec3::Z, Vec3::new(0.0, 1.0, 1.0)));
        assert!(!up_is_usable(-Vec3::Z, Vec3::Z * 3.0));
        assert!(!up_is_usable(Vec3::new(0.0, -2.0, 0.0), Vec3::Y));
    }
}
