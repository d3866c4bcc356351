//! The host copy of a G-buffer: plain data, no GPU. The renderer reads it
//! back ([`crate::render::Renderer::render_with_gbuffer`]); the CPU
//! references ([`crate::reference`], [`crate::fields`]), the EXR passes and
//! the tests read it from here.

/// A G-buffer read back to the host (guard band included), for CPU
/// references and tests.
#[derive(Debug, Clone)]
pub struct HostGBuffer {
    pub width: u32,
    pub height: u32,
    pub guard: u32,
    /// Linear color, alpha = coverage.
    pub color: Vec<[f32; 4]>,
    /// (0, 0, z, coverage): eye depth (DESIGN §2's eye space; +inf for
    /// background) and covered fraction; x and y are not kept.
    pub eye: Vec<[f32; 4]>,
}

impl HostGBuffer {
    /// A `width` × `height` G-buffer without guard band, every texel zero:
    /// what the tiles of a frame are pasted into.
    pub fn zeroed(width: u32, height: u32) -> HostGBuffer {
        HostGBuffer {
            width,
            height,
            guard: 0,
            color: vec![[0.0; 4]; width as usize * height as usize],
            eye: vec![[0.0; 4]; width as usize * height as usize],
        }
    }

    /// Copies the interior (guard band left out) of `part`, the G-buffer of
    /// the output pixels from column `x`, row `y`, into this guard-less
    /// G-buffer of the whole frame.
    pub fn paste_interior(&mut self, part: &HostGBuffer, x: u32, y: u32) {
        let g = part.guard as usize;
        let w = (part.width - 2 * part.guard) as usize;
        for row in 0..(part.height - 2 * part.guard) as usize {
            let from = (row + g) * part.width as usize + g;
            let to = (y as usize + row) * self.width as usize + x as usize;
            self.color[to..to + w].copy_from_slice(&part.color[from..from + w]);
            self.eye[to..to + w].copy_from_slice(&part.eye[from..from + w]);
        }
    }
}
