//! The thin-lens camera of DESIGN §2: pose, projection, circle of confusion,
//! lens offset, the camera file and its defaults (auto-framing, automatic
//! aperture).
//!
//! This is the only place the lens formulas live on the CPU; `glsl/lens.glsl`
//! mirrors them and the tests compare the GPU against these functions.
//!
//! Conventions (DESIGN §2): lengths in scene units; eye space has x right,
//! y up and z > 0 *in front of* the eye (not glam's −z view space); pixel
//! coordinates have their origin at the top-left corner, x right, y down, and
//! pixel centres at +0.5. The lens is the fixed-field-of-view thin lens of
//! pbrt, Mitsuba and Cycles: the projection does not breathe with focus.
//!
//! The module is split by job; everything is re-exported here, so the paths
//! are `pointlens::camera::X` whatever file `X` lives in:
//!
//! * `lens`: the resolved [`Camera`] and the thin-lens maths (basis, f_px,
//!   the world → eye transform [`EyeFromWorld`], projection, CoC, lens
//!   offset, guard band).
//! * `tables`: the lens sample and bin tables: the concentric map
//!   ([`concentric_disk`], [`concentric_square`]), the ray distribution
//!   buffer's lens cells ([`rdb_lens_table`], [`rdb_bin`]) and
//!   [`lens_samples`].
//! * `aperture`: the aperture's shape ([`Aperture`], its flags and
//!   fields [`ApertureSpec`], an [`ApertureImage`]): the transmission
//!   T(u), the cat's eye and the lens samples that follow the shape.
//! * `file`: the camera file: [`CameraSpec`], parsing, overrides,
//!   completeness and value checks, the cloud-free defaults
//!   ([`DEFAULT_WIDTH`], [`DEFAULT_HEIGHT`], [`DEFAULT_FOVY_DEG`]) and
//!   [`Camera::to_spec`] / [`Camera::to_json`].
//! * `framing`: [`resolve`], with auto-framing ([`FRAMING_MARGIN`]) and the
//!   automatic aperture.

mod aperture;
mod file;
mod framing;
mod lens;
mod tables;

pub use aperture::{
    Aperture, ApertureFeature, ApertureImage, ApertureSpec, ShapeRows, ShapeSpans,
    APERTURE_FEATURES, MAX_APERTURE_IMAGE_SIDE, MAX_BLADES,
};
pub use file::{
    CameraSpec, Coordinates, DEFAULT_FOVY_DEG, DEFAULT_HEIGHT, DEFAULT_WIDTH, MAX_PIXELS,
    MAX_SIDE_PX,
};
pub use framing::{resolve, resolve_for, FRAMING_MARGIN, Z_UP_VIEW_DOWN_DEG};
pub use lens::{Camera, EyeFromWorld, MAX_GUARD_PX};
pub use tables::{
    concentric_disk, concentric_square, lens_samples, pixel_jitters, rdb_bin, rdb_lens_table,
    square_cell,
};
