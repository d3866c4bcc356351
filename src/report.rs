//! The timing report of one rendered frame (`render --timings`,
//! `--timings-json`): serde types shared with `bench`'s report.

use serde::{Deserialize, Serialize};

use crate::vk::{DeviceInfo, FrameTimings, PassTiming};

/// The device a measurement was taken on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DeviceReport {
    pub name: String,
    pub driver: String,
    pub driver_info: String,
    pub driver_version: u32,
    pub api_version: String,
    pub device_type: String,
}

impl DeviceReport {
    pub fn of(info: &DeviceInfo) -> DeviceReport {
        let v = info.api_version;
        DeviceReport {
            name: info.name.clone(),
            driver: info.driver_name.clone(),
            driver_info: info.driver_info.clone(),
            driver_version: info.driver_version,
            api_version: format!(
                "{}.{}.{}",
                ash::vk::api_version_major(v),
                ash::vk::api_version_minor(v),
                ash::vk::api_version_patch(v)
            ),
            device_type: format!("{:?}", info.device_type),
        }
    }
}

fn one() -> u32 {
    1
}

/// The upload of a cloud (once per scene, not part of any frame).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Upload {
    /// Splat sizes on the CPU: the splat hierarchy's local spacing (before
    /// the hierarchy: the k-nearest-neighbour spacing; 0 in reports written
    /// before it was measured apart).
    #[serde(default)]
    pub splat_sizes_ms: f64,
    /// Building the splat hierarchy, splat sizes included (0 in reports
    /// written before it existed).
    #[serde(default)]
    pub tree_ms: f64,
    /// Host bytes of the hierarchy, every level.
    #[serde(default)]
    pub tree_bytes: u64,
    /// The copy to device memory, GPU time (0 since the hierarchy: the
    /// splats go to the GPU per frame).
    pub gpu_ms: f64,
    /// All of it.
    pub wall_ms: f64,
}

/// The splat hierarchy's work for one frame (DESIGN §3): the LOD rule,
/// nodes tested, splats emitted, and the times on the CPU.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct LodReport {
    pub lod_px: f32,
    pub lod_blur: Option<f32>,
    /// Whether the nodes facing away from the lens were dropped
    /// (`--cull-back-faces`).
    #[serde(default)]
    pub cull_back_faces: bool,
    pub nodes_visited: u64,
    pub splats_emitted: u64,
    /// Inner nodes among the emitted splats.
    pub inner_emitted: u64,
    pub traversal_ms: f64,
    /// Measuring the emitted splats (depth range, largest splat) and
    /// copying them to a buffer the GPU reads.
    pub splats_upload_ms: f64,
    /// Whether the splats came from the last frame's (same camera and
    /// rule): no traversal in this frame.
    #[serde(default)]
    pub cached: bool,
    /// Splats too near the lens for the G-buffer, composited as a veil
    /// instead (`crate::veil`).
    #[serde(default)]
    pub veiled: u64,
}

/// The count a frame of 3D Gaussians reports its tile entries under (the
/// most of any lens point).
pub const GAUSSIAN_TILE_ENTRIES: &str = "gaussians.tile_entries";
/// The count of a Gaussian frame's report: centres in front of the near
/// plane (`GpuGaussians::near_z`), before the view's sides cull.
pub const GAUSSIANS_IN_FRONT: &str = "gaussians.in_front";

/// One rendered frame: what was rendered, each pass's GPU time, the frame's
/// wall time, and the work around the frame measured apart.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameReport {
    pub device: DeviceReport,
    /// The method as `bench` names it (`rdb9`, `fast-uniform-tree`, `accum256`, …).
    pub method: String,
    pub width: u32,
    pub height: u32,
    pub ssaa: u32,
    /// Samples of a pixel per G-buffer raster pass (DESIGN §3; K² for the
    /// upscaled plan; 1 in reports written before multisampled passes).
    #[serde(default = "one")]
    pub samples_per_pass: u32,
    pub points: usize,
    pub guard_px: u32,
    /// Per pass name, in recording order: GPU time summed over its scopes.
    pub passes: Vec<PassTiming>,
    /// What the method counted in the frame (name, value): the layered
    /// method's slices and kept and discarded pixels per layer.
    #[serde(default)]
    pub counts: Vec<(String, u64)>,
    /// The splat hierarchy's work for the frame.
    #[serde(default)]
    pub lod: LodReport,
    pub gpu_total_ms: f64,
    pub frame_wall_ms: f64,
    /// The part of the frame's wall spent copying its pixels from the
    /// readback buffer to the host's image (0 in reports written before
    /// it was measured).
    #[serde(default)]
    pub readback_ms: f64,
    pub upload: Upload,
    /// Reading the cloud file.
    pub load_ms: f64,
    /// Encoding and writing the output image.
    pub encode_ms: f64,
    /// A frame of 3D Gaussians: `points` counts Gaussians, and there is no
    /// splat hierarchy (false in reports written before them).
    #[serde(default)]
    pub gaussians: bool,
}

impl FrameReport {
    /// The frame's timings with the facts around them.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        device: &DeviceInfo,
        method: String,
        (width, height): (u32, u32),
        ssaa: u32,
        points: usize,
        guard_px: u32,
        frame: &FrameTimings,
        upload: Upload,
    ) -> FrameReport {
        FrameReport {
            device: DeviceReport::of(device),
            method,
            width,
            height,
            ssaa,
            samples_per_pass: 1,
            points,
            guard_px,
            passes: frame.passes.clone(),
            counts: Vec::new(),
            lod: LodReport::default(),
            gpu_total_ms: frame.gpu_total_ms(),
            frame_wall_ms: frame.wall_ms,
            readback_ms: frame.readback_ms,
            upload,
            load_ms: 0.0,
            encode_ms: 0.0,
            gaussians: false,
        }
    }

    /// Whether the frame drew nothing of the scene (the background alone):
    /// no splat in view, or no Gaussian on any tile.
    pub fn drew_nothing(&self) -> bool {
        match self.gaussians {
            true => self
                .counts
                .iter()
                .any(|(name, n)| name == GAUSSIAN_TILE_ENTRIES && *n == 0),
            false => self.lod.splats_emitted == 0 && self.lod.veiled == 0,
        }
    }

    /// The report as `--timings` prints it: a table of passes, then the
    /// totals and the work outside the frame.
    pub fn text(&self) -> String {
        let d = &self.device;
        let mut s = format!(
            "device: {} ({} {})\nframe: {}x{} method {} ssaa {} ({} per raster pass) {} {} guard {} px\n",
            d.name,
            d.driver,
            d.driver_info,
            self.width,
            self.height,
            self.method,
            self.ssaa,
            self.samples_per_pass,
            if self.gaussians { "gaussians" } else { "points" },
            self.points,
            self.guard_px
        );
        s += &format!("{:<20} {:>10} {:>6}\n", "pass", "gpu ms", "count");
        for p in &self.passes {
            s += &format!("{:<20} {:>10.3} {:>6}\n", p.name, p.gpu_ms, p.count);
        }
        s += &format!("{:<20} {:>10.3}\n", "gpu total", self.gpu_total_ms);
        for (name, value) in &self.counts {
            s += &format!("{name:<28} {value:>10}\n");
        }
        let l = &self.lod;
        if self.gaussians {
            s += &format!("{:<20} {:>10.3}\n", "frame wall", self.frame_wall_ms);
            s += &self.host_line();
            for (name, ms) in [("load wall", self.load_ms), ("encode wall", self.encode_ms)] {
                s += &format!("{name:<20} {ms:>10.3}   (not in the frame)\n");
            }
            return s;
        }
        let mut rule = match l.lod_blur {
            Some(f) => format!("lod-px {} lod-blur {f}", l.lod_px),
            None => format!("lod-px {}", l.lod_px),
        };
        if l.cull_back_faces {
            rule += ", back faces culled";
        }
        let cached = if l.cached { " (last frame's)" } else { "" };
        s += &format!(
            "splats: {} emitted ({} inner nodes), {} nodes visited, {rule}{cached}\n",
            l.splats_emitted, l.inner_emitted, l.nodes_visited
        );
        if l.veiled > 0 {
            s += &format!("splats too near the lens, drawn as a veil: {}\n", l.veiled);
        }
        s += &format!("{:<20} {:>10.3}\n", "traversal wall", l.traversal_ms);
        s += &format!(
            "{:<20} {:>10.3}\n",
            "splats upload wall", l.splats_upload_ms
        );
        s += &format!("{:<20} {:>10.3}\n", "frame wall", self.frame_wall_ms);
        s += &self.host_line();
        if self.points > 0 && self.upload.tree_bytes > 0 {
            s += &format!(
                "tree: {} bytes, {:.1} per point (every level)\n",
                self.upload.tree_bytes,
                self.upload.tree_bytes as f64 / self.points as f64
            );
        }
        for (name, ms) in [
            ("upload gpu", self.upload.gpu_ms),
            ("splat sizes wall", self.upload.splat_sizes_ms),
            ("tree build wall", self.upload.tree_ms),
            ("load wall", self.load_ms),
            ("encode wall", self.encode_ms),
        ] {
            s += &format!("{name:<20} {ms:>10.3}   (not in the frame)\n");
        }
        s
    }

    /// The frame's host share, ms: its wall time less its GPU time
    /// (recording, allocation, submission, waiting, readback; on a CPU
    /// device the two overlap less than on a GPU).
    pub fn host_ms(&self) -> f64 {
        (self.frame_wall_ms - self.gpu_total_ms).max(0.0)
    }

    /// The `--timings` lines of [`FrameReport::host_ms`], with its share of
    /// the frame, and of the readback's copy within it.
    fn host_line(&self) -> String {
        let share = match self.frame_wall_ms > 0.0 {
            true => 100.0 * self.host_ms() / self.frame_wall_ms,
            false => 0.0,
        };
        format!(
            "{:<20} {:>10.3}   ({share:.0} % of the frame wall)\n{:<20} {:>10.3}   (of the host share)\n",
            "host (wall - gpu)",
            self.host_ms(),
            "readback copy",
            self.readback_ms
        )
    }

    /// The report as pretty-printed JSON (`--timings-json`).
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a frame report always serialises") + "\n"
    }
}

/// This process's host memory, bytes: (resident now, peak resident), from
/// `/proc/self/status` (Linux; None elsewhere). `render -v` logs it per
/// frame, the long-run test reads it.
pub fn host_memory_bytes() -> Option<(u64, u64)> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let field = |name: &str| -> Option<u64> {
        let line = status.lines().find(|l| l.starts_with(name))?;
        let kb: u64 = line[name.len()..]
            .trim()
            .trim_end_matches("kB")
            .trim()
            .parse()
            .ok()?;
        Some(kb * 1024)
    };
    Some((field("VmRSS:")?, field("VmHWM:")?))
}
