//! The thin-lens maths of DESIGN §2: the resolved [`Camera`], its eye basis,
//! focal length in pixels, world → eye transform, pinhole projection,
//! circle of confusion and THE lens-position ↔ image-offset relation.

use glam::{Vec2, Vec3};

use super::Aperture;

/// The resolved thin-lens camera of DESIGN §2.
///
/// Built by [`resolve`] from a [`CameraSpec`], or directly. `up` need not be
/// unit length nor perpendicular to the view direction; [`Camera::basis`]
/// orthonormalises it.
///
/// [`resolve`]: super::resolve
/// [`CameraSpec`]: super::CameraSpec
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Centre of the lens, in world space.
    pub eye: Vec3,
    /// Point the camera looks at.
    pub target: Vec3,
    /// Approximate up direction of the image.
    pub up: Vec3,
    /// Vertical field of view θ in degrees, in (0, 180).
    pub fovy_deg: f32,
    /// Lens aperture radius R in scene units (0: a pinhole).
    pub aperture_radius: f32,
    /// Focus distance S: the eye-space depth of the plane in focus (> 0).
    pub focus_distance: f32,
    /// The aperture's shape within the lens's circle of radius R
    /// ([`Aperture::ROUND`]: DESIGN §2's round lens).
    pub aperture: Aperture,
}

/// The widest guard band of any frame, pixels: a quarter of 16384 px,
/// the largest image of lavapipe and of desktop GPUs (NVIDIA's is 32768;
/// Vulkan's minimum, 4096, holds no band this wide), so that a tile of up
/// to 8192 px with the band fits such a device ([`Camera::max_guard_px`]).
/// Frames up to 8192 px wide and high are not bounded by it.
pub const MAX_GUARD_PX: u32 = 4096;

impl Camera {
    /// The orthonormal eye basis `(right, up', forward)`:
    /// forward = normalize(target − eye); right = normalize(forward × up);
    /// up' = right × forward.
    pub fn basis(&self) -> (Vec3, Vec3, Vec3) {
        let forward = (self.target - self.eye).normalize();
        let right = forward.cross(self.up).normalize();
        let up = right.cross(forward);
        (right, up, forward)
    }

    /// Focal length in pixels: f_px = (H / 2) / tan(θ / 2).
    pub fn f_px(&self) -> f32 {
        (self.height as f32 / 2.0) / (self.fovy_deg.to_radians() / 2.0).tan()
    }

    /// The world → eye transform of [`Camera::eye_from_world`], with the
    /// basis computed once: for callers that transform many points.
    pub fn eye_from_world_transform(&self) -> EyeFromWorld {
        let (right, up, forward) = self.basis();
        EyeFromWorld {
            eye: self.eye,
            right,
            up,
            forward,
        }
    }

    /// Eye-space coordinates of the world point `p`:
    /// (x, y, z) = ((p − eye)·right, (p − eye)·up', (p − eye)·forward).
    /// z > 0 in front of the eye (DESIGN §2; not glam's −z view space).
    ///
    /// Recomputes the basis on every call; to transform many points, make
    /// the [`EyeFromWorld`] once with [`Camera::eye_from_world_transform`].
    pub fn eye_from_world(&self, p: Vec3) -> Vec3 {
        self.eye_from_world_transform().apply(p)
    }

    /// Pinhole projection of the world point `p`: its pixel position
    /// (x_px = W/2 + f_px·x/z, y_px = H/2 − f_px·y/z; origin top-left, pixel
    /// centres at +0.5) and its eye depth z. `None` when z ≤ 0 (at or behind
    /// the eye).
    pub fn project(&self, p: Vec3) -> Option<(Vec2, f32)> {
        let e = self.eye_from_world(p);
        if e.z.is_nan() || e.z <= 0.0 {
            return None;
        }
        Some((self.pixel_of_eye(e), e.z))
    }

    /// The pixel position of eye-space point `e` (z > 0) under
    /// [`Camera::project`]: for callers that hold eye coordinates.
    pub fn pixel_of_eye(&self, e: Vec3) -> Vec2 {
        let f = self.f_px();
        Vec2::new(
            self.width as f32 / 2.0 + f * e.x / e.z,
            self.height as f32 / 2.0 - f * e.y / e.z,
        )
    }

    /// Circle-of-confusion diameter in pixels of a point at eye depth `z`:
    /// c_px(z) = 2R · f_px · |z − S| / (z · S).
    ///
    /// `z = +∞` is the background (DESIGN §2): c_px(∞) = 2R · f_px / S.
    /// Defined for z > 0.
    pub fn coc_px(&self, z: f32) -> f32 {
        let (r, s) = (self.aperture_radius, self.focus_distance);
        if z == f32::INFINITY {
            return 2.0 * r * self.f_px() / s;
        }
        2.0 * r * self.f_px() * (z - s).abs() / (z * s)
    }

    /// Which way a point at depth `z` moves with the lens position:
    /// +1 behind the focus plane (z > S), −1 in front of it (z < S).
    ///
    /// At z = S this returns +1; the CoC, and with it the offset, is zero
    /// there, so the choice does not matter; `glsl/lens.glsl` makes the same one.
    pub fn lens_sign(&self, z: f32) -> f32 {
        if z >= self.focus_distance {
            1.0
        } else {
            -1.0
        }
    }

    /// The signed CoC diameter (pixels) at eye depth `z`: `lens_sign(z) ·
    /// coc_px(z)`, negative in front of the focus plane; it increases with
    /// depth, so it orders points by depth.
    pub fn signed_coc_px(&self, z: f32) -> f32 {
        self.lens_sign(z) * self.coc_px(z)
    }

    /// THE lens-position ↔ image-offset relation of DESIGN §2, the one
    /// function the accumulation reference (sheared projection) and the ray
    /// distribution buffer (bin of a pair) are built on.
    ///
    /// A point at eye depth `z` whose pinhole projection is p is seen, through
    /// the normalised lens position `u` (|u| ≤ 1, in pixel axes: x right,
    /// y down), at p + `lens_offset_px(z, u)`, where
    /// `lens_offset_px(z, u) = sign(z) · (c_px(z) / 2) · u`.
    /// A point behind the focus plane moves with u, one in front of it against
    /// u, one on it not at all (the focus plane stays fixed).
    pub fn lens_offset_px(&self, z: f32, u: Vec2) -> Vec2 {
        (self.signed_coc_px(z) / 2.0) * u
    }

    /// The largest CoC diameter (pixels) over the eye-depth range
    /// [`z_min`, `z_max`], 0 < z_min ≤ z_max. The CoC decreases towards the
    /// focus plane from both sides, so the maximum is at one end of the
    /// range; `z_max = +∞` includes the background.
    pub fn max_coc_px(&self, z_min: f32, z_max: f32) -> f32 {
        self.coc_px(z_min).max(self.coc_px(z_max))
    }

    /// Guard band in pixels around the frame (DESIGN §3):
    /// ⌈max CoC / 2 + max splat / 2⌉, both arguments in pixels, bounded by
    /// [`Camera::max_guard_px`] (a NaN or infinite argument gives the
    /// bound).
    pub fn guard_band_px(&self, max_coc_px: f32, max_splat_px: f32) -> u32 {
        let wanted = (max_coc_px / 2.0 + max_splat_px / 2.0).ceil();
        let bound = self.max_guard_px();
        if wanted.is_nan() || wanted >= bound as f32 {
            bound
        } else {
            wanted.max(0.0) as u32
        }
    }

    /// The widest guard band a frame gets: ⌈max(W, H) / 2⌉ pixels, so the
    /// G-buffer is at most twice the frame on each axis, and never more
    /// than [`MAX_GUARD_PX`], so that a tile of a poster with its band fits
    /// the device's images (DESIGN §3: the band stops at a size tied to the
    /// frame; docs/ARCHITECTURE.md, "Every camera renders" and "Posters in
    /// tiles"). Light from beyond it reaches the frame only through CoCs
    /// wider than the bound's double, spread at most 1/(π·bound²) per
    /// pixel each.
    pub fn max_guard_px(&self) -> u32 {
        self.width.max(self.height).div_ceil(2).min(MAX_GUARD_PX)
    }

    /// The CoC (pixels) above which a point in front of the focus plane
    /// is a veil ([`crate::veil::split`]) for the methods that blur a
    /// G-buffer: the widest blur the largest guard band holds on both
    /// sides of a pixel, 2 · [`Camera::max_guard_px`].
    pub fn veil_coc_px(&self) -> f32 {
        2.0 * self.max_guard_px() as f32
    }
}

/// The camera's world → eye transform, made once for many points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EyeFromWorld {
    eye: Vec3,
    right: Vec3,
    up: Vec3,
    forward: Vec3,
}

impl EyeFromWorld {
    /// Eye-space coordinates of `p` (see Camera::eye_from_world).
    pub fn apply(&self, p: Vec3) -> Vec3 {
        let d = p - self.eye;
        Vec3::new(d.dot(self.right), d.dot(self.up), d.dot(self.forward))
    }
}
