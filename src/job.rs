//! A render job: the frames of a shot (one image, a `--frames` motion or a
//! `--path` camera path), each resolved to a camera, rendered, and written
//! atomically, with its timing report. `pointlens render` is this module
//! behind its flags; tests and library users call it directly.
//!
//! The steps, in the order `main` takes them:
//!
//! 1. [`RenderJob::new`] checks what needs no cloud: the output name
//!    against the shot (a `%04d` pattern for a sequence, none for one
//!    image), `--frame-range`, every frame's folder, the timings file's
//!    folder, EXR passes, the level of detail. A mistake fails here, before
//!    a cloud is read.
//! 2. [`watch_signals`] makes SIGINT and SIGTERM safe (no partial file).
//! 3. [`RenderJob::plan`] resolves every frame's camera against the loaded
//!    cloud (a bad keyframe fails the run before the first frame) and drops
//!    the frames whose file exists under `--skip-existing`.
//! 4. [`RenderJob::render`] renders and writes the planned frames on a
//!    [`Renderer`], reporting each through [`JobEvent`]s, and stops between
//!    frames when asked to; [`RenderJob::write_timings`] writes the reports.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use glam::{DVec3, Vec3};

use crate::camera::{self, Camera, CameraSpec, Coordinates};
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::gaussian_render::{GaussianRenderer, GpuGaussians};
use crate::host_gbuffer::HostGBuffer;
use crate::image_io::{
    check_output_path, check_parent_dir, is_png_path, write_exr_channels, write_image,
    write_png_rgba, write_text_atomically, ExrChannel, LinearImage, Srgb8Image,
};
use crate::options::{check_lod, Lod, Method};
use crate::render::{RenderOptions, Rendered, Renderer, Scene};
use crate::report::FrameReport;
use crate::scene::{self, DeviceSetup, HostScene, SceneKind, SceneSpec, Scenes};
use crate::sequence::{CameraPath, FramePattern, FrameRange, Motion};
use crate::video::VideoWriter;
use crate::vk::ContextOptions;

/// What is rendered: one image, or a sequence of numbered ones.
#[derive(Debug, Clone)]
pub enum Shot {
    /// One image of the camera the flags and camera file give.
    Single,
    /// `--frames N` changed by `--orbit`, focus and aperture pulls.
    Motion(Motion),
    /// `--path FILE`: keyframes, from its first frame to its last.
    Path { file: PathBuf, path: CameraPath },
}

impl Shot {
    /// The frame numbers, first and last.
    pub fn frames(&self) -> (u32, u32) {
        match self {
            Shot::Single => (1, 1),
            Shot::Motion(m) => m.frames(),
            Shot::Path { path, .. } => path.frames(),
        }
    }

    /// The shot of the flags: `--path FILE` (its keyframes read), else
    /// `--frames N` with its motion, else one image.
    pub fn of(path: Option<&Path>, motion: Option<Motion>) -> Result<Shot> {
        Ok(match (path, motion) {
            (Some(file), _) => Shot::Path {
                file: file.to_path_buf(),
                path: CameraPath::from_json_file(file)?,
            },
            (None, Some(motion)) => Shot::Motion(motion),
            (None, None) => Shot::Single,
        })
    }

    /// Whether the shot numbers its frames (any but [`Shot::Single`]).
    pub fn is_sequence(&self) -> bool {
        !matches!(self, Shot::Single)
    }
}

/// EXR channels written beside R, G, B, A (`--passes`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Passes {
    /// `Z`: eye depth of the nearest surface, scene units (+∞ on background).
    pub z: bool,
    /// `CoC`: its circle of confusion, pixels.
    pub coc: bool,
}

/// What a frame's file holds besides the color.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Written {
    /// Alpha = coverage, color premultiplied in EXR and straight in PNG
    /// (`--background transparent`); else opaque.
    pub transparent: bool,
    pub passes: Passes,
}

/// Everything a render job is asked for (the flags of `pointlens render`
/// beyond the input, the scene's splat size and the device).
#[derive(Debug, Clone)]
pub struct JobSpec {
    pub shot: Shot,
    /// The output file, or for a sequence a pattern with a frame number
    /// (`shot_%04d.png`).
    pub output: PathBuf,
    /// `--frame-range`: only these frames of the sequence.
    pub frame_range: Option<FrameRange>,
    /// `--skip-existing`: leave frames whose file exists.
    pub skip_existing: bool,
    /// A camera file, read when the cloud is loaded ([`RenderJob::plan`]).
    pub camera_file: Option<PathBuf>,
    /// The camera flags: they win over the camera file and the path.
    pub camera_flags: CameraSpec,
    /// `--focus-pixel X,Y`: focus every frame on what that pixel sees.
    pub focus_pixel: Option<[u32; 2]>,
    pub method: Method,
    /// K: K×K G-buffer samples per pixel (None: the default of the frame's
    /// method and raster, [`Renderer::ssaa`]; of a scene of 3D Gaussians,
    /// 1).
    pub ssaa: Option<u32>,
    /// The most samples one raster pass takes (None: the device's best).
    pub samples_per_pass: Option<u32>,
    /// Linear-light background color.
    pub background: Vec3,
    pub lod: Lod,
    pub written: Written,
    /// `--timings-json`: every frame's report, written at the end.
    pub timings_json: Option<PathBuf>,
    /// `--fps`: a video's frame rate (None: [`crate::video::DEFAULT_FPS`];
    /// only with a video output).
    pub fps: Option<u32>,
}

/// A checked job ([`RenderJob::new`]).
#[derive(Debug, Clone)]
pub struct RenderJob {
    spec: JobSpec,
    /// Where the frames go when `-o` names a video.
    video: Option<Arc<VideoSink>>,
    pattern: Option<FramePattern>,
    /// The file of a single image: `-o` with `%%` read as `%`.
    single: PathBuf,
    range: FrameRange,
}

/// One frame to render: its number, camera and output file.
#[derive(Debug, Clone)]
pub struct FrameJob {
    pub number: u32,
    pub camera: Camera,
    pub output: PathBuf,
}

/// The frames of a job for one cloud ([`RenderJob::plan`]).
#[derive(Debug, Clone)]
pub struct Plan {
    /// The frames to render, in order (skipped ones left out).
    pub frames: Vec<FrameJob>,
    /// Frames of the range whose file existed (`--skip-existing`).
    pub skipped: usize,
    /// The coordinates and origin cameras are printed in.
    coordinates: Coordinates,
    origin: DVec3,
}

/// What [`RenderJob::render`] tells as it goes.
#[derive(Debug)]
pub enum JobEvent<'a> {
    /// A frame's camera, as it will be rendered (focus resolved), in the
    /// job's coordinates: before the frame renders.
    Camera { number: u32, spec: &'a CameraSpec },
    /// The reading of a file read whole: `done` of `total` points.
    Loading { done: u64, total: u64 },
    /// The scene is on the device and `frames` frames follow.
    Planned { frames: usize },
    /// Something the user should know: a frame that shows nothing of the
    /// scene, or how many did.
    Warning(&'a str),
    /// A frame written.
    Written {
        number: u32,
        output: &'a Path,
        seconds: f64,
        report: &'a FrameReport,
    },
}

/// What a job tells as it renders ([`RenderJob::render`]).
pub type Events<'a> = dyn FnMut(JobEvent) -> Result<()> + 'a;

/// What [`RenderJob::render`] did.
#[derive(Debug, Clone, Default)]
pub struct Outcome {
    /// Each frame's report, in order.
    pub reports: Vec<FrameReport>,
    /// Each frame's camera as rendered (number, camera in the job's
    /// coordinates): `--print-camera` of a sequence prints them as a path.
    pub cameras: Vec<(u32, CameraSpec)>,
}

/// `path` with its folder resolved (links, `.` and `..`): two names of one
/// file resolve alike. The folder exists (checked before).
fn resolved_file(path: &Path) -> Option<PathBuf> {
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    Some(std::fs::canonicalize(parent).ok()?.join(path.file_name()?))
}

impl RenderJob {
    /// Checks `spec` before any cloud is read: the output's format and name
    /// against the shot, the motion's numbers, the frame range, the folder
    /// of every frame's file and of the timings file, EXR passes (EXR only)
    /// and the level of detail.
    pub fn new(spec: JobSpec) -> Result<RenderJob> {
        // The fast method's options, checked before any cloud is read
        // (the frame checks them again).
        if let Method::Fast(fast) = spec.method {
            fast.check()?;
        }
        let video = VideoSink::for_job(&spec)?;
        if video.is_none() {
            check_output_path(&spec.output)?;
        }
        if let Shot::Motion(motion) = &spec.shot {
            motion.check()?;
        }
        let pattern = FramePattern::parse(&spec.output)?;
        let sequence = spec.shot.is_sequence();
        let output = spec.output.display();
        match (&pattern, sequence) {
            (None, true) if video.is_some() => {}
            (None, true) => {
                return Err(invalid(format!(
                    "-o {output}: a sequence needs a frame number in the output name, \
                     e.g. shot_%04d.png"
                )))
            }
            (Some(_), false) => {
                return Err(invalid(format!(
                    "-o {output}: a frame number pattern, but one frame to render \
                     (add --frames N or --path FILE)"
                )))
            }
            _ => {}
        }
        if !sequence && (spec.frame_range.is_some() || spec.skip_existing) {
            return Err(invalid(
                "--frame-range and --skip-existing are for sequences (--frames N or --path FILE)",
            ));
        }
        let range = match spec.frame_range {
            Some(r) => r.within(spec.shot.frames())?,
            None => {
                let (first, last) = spec.shot.frames();
                FrameRange { first, last }
            }
        };
        let single = match &pattern {
            Some(_) => spec.output.clone(),
            None => FramePattern::single_image(&spec.output)?,
        };
        let job = RenderJob {
            spec,
            video,
            pattern,
            single,
            range,
        };
        job.check_folders()?;
        if job.spec.written.passes != Passes::default()
            && (job.video.is_some() || is_png_path(&job.spec.output)?)
        {
            return Err(invalid("--passes writes EXR channels: use an .exr output"));
        }
        check_lod(&job.spec.lod)?;
        Ok(job)
    }

    /// What was asked.
    pub fn spec(&self) -> &JobSpec {
        &self.spec
    }

    /// Whether the job renders a sequence.
    pub fn is_sequence(&self) -> bool {
        self.spec.shot.is_sequence()
    }

    /// The frames of the range, first and last.
    pub fn range(&self) -> FrameRange {
        self.range
    }

    /// The output file of frame `number`.
    pub fn output_of(&self, number: u32) -> PathBuf {
        match &self.pattern {
            Some(p) => p.path(number),
            None => self.single.clone(),
        }
    }

    /// Every frame's folder (a pattern may number folders: out_%02d/f.png)
    /// and the timings file's, so a long run does not end without a place
    /// for its result. The timings file may not be a frame's image (it would
    /// replace it).
    fn check_folders(&self) -> Result<()> {
        let timings = match &self.spec.timings_json {
            Some(p) => {
                check_parent_dir(p, "--timings-json")?;
                Some((p, resolved_file(p)))
            }
            None => None,
        };
        let mut last_dir = None;
        for number in self.range.first..=self.range.last {
            let output = self.output_of(number);
            if output.parent() != last_dir.as_deref() {
                check_parent_dir(&output, "-o")?;
                last_dir = output.parent().map(Path::to_path_buf);
            }
            if let Some((path, resolved)) = &timings {
                // Folders are resolved (I/O) only for a frame of the same
                // file name: not once per frame of a long sequence.
                if resolved.is_some()
                    && output.file_name() == path.file_name()
                    && *resolved == resolved_file(&output)
                {
                    return Err(invalid(format!(
                        "--timings-json {} is the image of frame {number} (-o {}): name another file",
                        path.display(),
                        output.display()
                    )));
                }
            }
        }
        Ok(())
    }

    /// The camera fields of frame `number`: the camera file's, then the
    /// path's, then the flags'.
    fn spec_of(&self, file: Option<&CameraSpec>, number: u32) -> Result<CameraSpec> {
        let mut spec = file.cloned().unwrap_or_default();
        if let Shot::Path { path, .. } = &self.spec.shot {
            spec = spec.overridden_by(&path.spec_at(number));
        }
        let spec = spec.overridden_by(&self.spec.camera_flags);
        if let Some(path) = &self.spec.camera_file {
            spec.require_complete()
                .map_err(|e| e.within(path.display().to_string()))?;
        }
        Ok(spec)
    }

    /// Every frame's camera through `cloud` (auto-framing, file
    /// coordinates), before any is rendered: a bad keyframe fails the run
    /// before the first frame. With `--skip-existing`, the frames whose
    /// file exists are left out (and logged).
    pub fn plan(&self, cloud: &PointCloud) -> Result<Plan> {
        let file = match &self.spec.camera_file {
            Some(path) => Some(CameraSpec::from_json_file(path)?),
            None => None,
        };
        let origin = cloud.origin;
        let (lo, hi) = cloud.bounds();
        let resolve = |spec: &CameraSpec| -> Result<Camera> {
            let in_scene = spec.in_scene(origin)?;
            camera::resolve_for(&in_scene, lo, hi, &cloud.positions, cloud.z_up)
        };
        let first_spec = self.spec_of(file.as_ref(), self.range.first)?;
        let coordinates = first_spec.coordinates.unwrap_or_default();
        let base = resolve(&first_spec)?;
        let mut frames = Vec::new();
        for number in self.range.first..=self.range.last {
            let camera = match &self.spec.shot {
                Shot::Single => base,
                Shot::Motion(motion) => motion.camera(&base, number),
                Shot::Path {
                    file: path_file, ..
                } => resolve(&self.spec_of(file.as_ref(), number)?)
                    .map_err(|e| e.within(format!("frame {number} of {}", path_file.display())))?,
            };
            camera
                .aperture
                .check_method(self.spec.method.kind(), false)?;
            frames.push(FrameJob {
                number,
                camera,
                output: self.output_of(number),
            });
        }
        let all = frames.len();
        if self.spec.skip_existing {
            frames.retain(|job| {
                let exists = job.output.exists();
                if exists {
                    log::info!(
                        "frame {}: {} exists, skipped",
                        job.number,
                        job.output.display()
                    );
                }
                !exists
            });
        }
        Ok(Plan {
            skipped: all - frames.len(),
            frames,
            coordinates,
            origin,
        })
    }

    /// The whole job on the scene `scene` describes: its flags checked
    /// against its kind ([`scene::check_flags`]), SIGINT and SIGTERM
    /// watched ([`watch_signals`]), the file read, every frame's camera
    /// planned, the device `device` opened and the scene uploaded, the
    /// frames rendered and written in order ([`scene::DeviceScene::render_frame`]),
    /// the timings written and the validation layer's count checked.
    /// `events` is told the reading's progress, the frames to come, each
    /// frame's camera and file, and warnings (a frame that shows nothing
    /// of the scene).
    pub fn run(
        &self,
        scene: &SceneSpec,
        device: &ContextOptions,
        events: &mut Events<'_>,
    ) -> Result<Outcome> {
        let kind = crate::input::kind_of(&scene.input);
        scene::check_flags(kind, &self.spec, scene)?;
        scene::check_lod_before_reading(kind, &self.spec.lod, scene)?;
        // Checked again by every frame; here before the file is read.
        if scene.edl.is_some() {
            crate::options::check_edl_with(&self.spec.method)?;
        }
        // The raster as far as the command line says (the device's
        // atomics are not known yet).
        let raster = crate::options::frame_raster(
            scene.raster.unwrap_or_default(),
            self.spec.samples_per_pass,
            None,
        )?;
        crate::options::check_coverage_with(
            scene.coverage,
            &self.spec.method,
            Some(raster),
            scene.splat_shape,
        )?;
        if kind == SceneKind::Gaussians {
            self.gaussian_lens(&camera::Aperture::ROUND)?;
        }
        // SIGINT or SIGTERM ends a sequence after the frame being rendered
        // (its file complete); a second one, or one during a single image,
        // ends the process at once, removing the file being written.
        let stop = Arc::new(AtomicBool::new(false));
        watch_signals(self.is_sequence(), stop.clone())?;
        // The device opens and makes its pipelines on a thread of its own
        // while the file is read and its hierarchy built.
        let method = self.spec.method;
        let ready = std::thread::scope(|threads| -> Result<Option<_>> {
            let setup = threads.spawn(|| DeviceSetup::open(device, kind, scene, &method));
            let t_load = Instant::now();
            let host = HostScene::open(scene, &mut |done, total| {
                // Progress only: an observer's error waits for the next event.
                let _ = events(JobEvent::Loading { done, total });
            })?;
            host.check_lod(&self.spec.lod, scene)?;
            let load_ms = t_load.elapsed().as_secs_f64() * 1e3;
            let plan = self.plan(host.framing())?;
            if let Some(video) = &self.video {
                video.check_plan(&plan)?;
            }
            if plan.frames.is_empty() {
                log::warn!(
                    "nothing to render: the {} frames' files exist",
                    plan.skipped
                );
                // The device, made for nothing, goes unused.
                return Ok(None);
            }
            let built = host.build(scene)?;
            let setup = setup
                .join()
                .unwrap_or_else(|panic| std::panic::resume_unwind(panic))?;
            Ok(Some((built, setup, plan, load_ms)))
        })?;
        let Some((built, setup, plan, load_ms)) = ready else {
            return Ok(Outcome::default());
        };
        let on_device = built.upload(setup, scene)?;
        let ctx = on_device.ctx().clone();
        events(JobEvent::Planned {
            frames: plan.frames.len(),
        })?;
        let outcome = self.run_frames(
            &ctx,
            &plan,
            &stop,
            events,
            WRITES_IN_FLIGHT,
            |job, events| on_device.render_frame(self, job, &plan, load_ms, events),
        );
        let outcome = self.finish_video(outcome)?;
        self.write_timings(&outcome.reports)?;
        // The device's scene goes before the validation layer's count.
        drop(on_device);
        ctx.check_validation()?;
        Ok(outcome)
    }

    /// Renders and writes the frames of `plan` in order on `renderer`:
    /// each frame's focus (`--focus-pixel`), its image and passes written
    /// atomically, its report (`load_ms`: the cloud's reading, for the
    /// reports), each step told to `events` (whose error ends the job).
    /// Before each frame, `stop` set (by [`watch_signals`]) ends the job
    /// with [`Error::Interrupted`], the frames before it complete.
    pub fn render(
        &self,
        renderer: &Renderer,
        scenes: Scenes<'_>,
        plan: &Plan,
        stop: &AtomicBool,
        load_ms: f64,
        events: &mut dyn FnMut(JobEvent) -> Result<()>,
    ) -> Result<Outcome> {
        let outcome = self.run_frames(renderer.ctx(), plan, stop, events, 0, |job, events| {
            self.point_frame(renderer, scenes, job, plan, load_ms, events)
        });
        self.finish_video(outcome)
    }

    /// A video's end: once every frame is in (`outcome` Ok), ffmpeg
    /// finishes the file, which takes its name; otherwise the video in
    /// writing is dropped with its temporary.
    fn finish_video(&self, outcome: Result<Outcome>) -> Result<Outcome> {
        let Some(video) = &self.video else {
            return outcome;
        };
        let writer = video
            .writer
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take();
        match (outcome, writer) {
            (Ok(outcome), Some(writer)) => {
                writer.finish()?;
                Ok(outcome)
            }
            (Err(Error::Interrupted { written, total, .. }), _) => Err(Error::VideoInterrupted {
                path: video.path.clone(),
                rendered: written,
                total,
            }),
            (outcome, _) => outcome,
        }
    }

    /// Renders frame `job` of a cloud's `scenes`, its camera told to
    /// `events` first: the camera as rendered, the report and the write of
    /// its file.
    pub fn point_frame(
        &self,
        renderer: &Renderer,
        scenes: Scenes<'_>,
        job: &FrameJob,
        plan: &Plan,
        load_ms: f64,
        events: &mut Events<'_>,
    ) -> Result<RenderedFrame> {
        // A COPC file's scene is the nodes of the frame's camera: chosen
        // again once `--focus-pixel` has moved the focus.
        let scene = scenes.for_camera(renderer, &job.camera, self.spec.lod)?;
        let options = self.frame_options(renderer, &scene, job.camera)?;
        let scene = match options.camera == job.camera {
            true => scene,
            false => {
                // One scene on the device at a time.
                drop(scene);
                scenes.for_camera(renderer, &options.camera, self.spec.lod)?
            }
        };
        let scene = &*scene;
        let spec = options.camera.to_spec_in(plan.coordinates, plan.origin);
        events(JobEvent::Camera {
            number: job.number,
            spec: &spec,
        })?;
        let (measure, write) = match &self.video {
            Some(video) => video_frame(renderer, scene, &options, video)?,
            None => render_frame(renderer, scene, &options, &job.output, self.spec.written)?,
        };
        let report = FrameReport {
            load_ms,
            ..measure.into_report(renderer, &self.spec, &options, scene)
        };
        Ok(RenderedFrame {
            spec,
            report,
            write,
        })
    }

    /// Runs `frame` on each frame of `plan` in order — it renders the
    /// frame, tells `events` its camera first, and returns the camera as
    /// rendered, the report and the write of its file — and writes the
    /// files in frame order: with `in_flight` 0 each before the next frame
    /// renders, else on a writer thread while the next frames render, at
    /// most `in_flight` frames rendered and not yet written. Tells `events`
    /// each file written, in frame order, and a warning for frames that
    /// drew nothing of the scene (the first by its number, the count at the
    /// end). Once `stop` is set, no frame is begun and no write that has
    /// not begun begins; the one in progress completes, and the error says
    /// how far the job got.
    fn run_frames<F>(
        &self,
        ctx: &crate::vk::Context,
        plan: &Plan,
        stop: &AtomicBool,
        events: &mut dyn FnMut(JobEvent) -> Result<()>,
        in_flight: usize,
        mut frame: F,
    ) -> Result<Outcome>
    where
        F: FnMut(&FrameJob, &mut Events<'_>) -> Result<RenderedFrame>,
    {
        use std::sync::mpsc;
        std::thread::scope(|scope| {
            // Each write's result, in frame order: None where `stop` came
            // before it began.
            let (to_job, results) = mpsc::channel::<Option<Result<f64>>>();
            let (to_writer, writes) = mpsc::sync_channel::<FileWrite>(in_flight.saturating_sub(1));
            let writer = (in_flight > 0).then(|| {
                let to_job = to_job.clone();
                scope.spawn(move || {
                    for write in writes {
                        let result = (!stop.load(Ordering::SeqCst)).then(|| timed_ms(write));
                        if to_job.send(result).is_err() {
                            break;
                        }
                    }
                })
            });
            let mut done = FilesWritten::default();
            let mut waiting = std::collections::VecDeque::new();
            let rendered = (|| {
                for job in &plan.frames {
                    if stop.load(Ordering::SeqCst) {
                        break;
                    }
                    let started = Instant::now();
                    let RenderedFrame {
                        spec,
                        report,
                        write,
                    } = frame(job, events)?;
                    waiting.push_back((job, started, spec, report));
                    match &writer {
                        Some(_) => to_writer.send(write).expect("the writer takes writes"),
                        None => to_job
                            .send(Some(timed_ms(write)))
                            .expect("the job's channel"),
                    }
                    while let Ok(result) = results.try_recv() {
                        let (job, started, spec, report) =
                            waiting.pop_front().expect("a frame a result");
                        done.finish(ctx, events, job, started, spec, report, result)?;
                    }
                }
                Ok(())
            })();
            drop(to_writer);
            // The frames rendered and not yet written: completed (or, after
            // `stop`, left unbegun) whatever else went wrong.
            let mut first_error = rendered.err();
            while let Some((job, started, spec, report)) = waiting.pop_front() {
                let result = results.recv().unwrap_or(None);
                if first_error.is_none() {
                    first_error = done
                        .finish(ctx, events, job, started, spec, report, result)
                        .err();
                } else if let Some(Err(e)) = result {
                    log::error!("frame {}: {e}", job.number);
                }
            }
            if let Some(writer) = writer {
                writer
                    .join()
                    .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
            }
            if let Some(e) = first_error {
                return Err(e);
            }
            let written = done.outcome.reports.len();
            if let Some(next) = plan.frames.get(written) {
                return Err(Error::Interrupted {
                    written,
                    total: plan.frames.len(),
                    next: next.number,
                });
            }
            if done.empty_frames > 1 {
                events(JobEvent::Warning(&format!(
                    "{} of {} frames showed nothing of the scene",
                    done.empty_frames,
                    plan.frames.len()
                )))?;
            }
            Ok(done.outcome)
        })
    }

    /// K of a scene of 3D Gaussians: `--ssaa`, else
    /// [`crate::options::DEFAULT_SSAA_GAUSSIANS`] (pixel centres, as trained).
    pub fn gaussian_ssaa(&self) -> u32 {
        self.spec
            .ssaa
            .unwrap_or(crate::options::DEFAULT_SSAA_GAUSSIANS)
    }

    /// The lens points of a Gaussian scene's method (the centre for
    /// `pinhole` and `layered`, the lens samples of `accum`); any other
    /// method is refused. (What else a Gaussian scene cannot do is in
    /// [`scene::FLAGS`].) `aperture`: the camera's, whose shape accum's
    /// lens samples follow. The points are in eye axes (x right, y up),
    /// as `GaussianRenderer::render` and `gaussians::render_reference_lens`
    /// take them.
    pub fn gaussian_lens(&self, aperture: &camera::Aperture) -> Result<Vec<glam::Vec2>> {
        match self.spec.method {
            m @ (Method::Pinhole | Method::Layered(_)) => {
                aperture.check_method(m.kind(), true)?;
                Ok(vec![glam::Vec2::ZERO])
            }
            Method::Accum(a) => {
                crate::options::check_samples(a.samples)?;
                // The Gaussian chain takes lens points in eye axes (x
                // right, y up); a shape's samples are in pixel axes (y
                // down), so they turn over. The round lattice is kept as
                // it was: any set of the disk's samples is the disk's.
                if aperture.is_round() {
                    return Ok(camera::lens_samples(a.samples));
                }
                let samples = aperture.lens_samples(a.samples);
                Ok(samples
                    .into_iter()
                    .map(|u| glam::Vec2::new(u.x, -u.y))
                    .collect())
            }
            m => Err(Error::InvalidArgument(format!(
                "--method {}: a scene of 3D Gaussians renders with pinhole, layered or accum",
                m.short_name()
            ))),
        }
    }

    /// Renders frame `job` of a Gaussian scene (`plan` made from its
    /// centres), its camera told to `events` first, as the point frames
    /// are: the camera as rendered, the report and the write of its file.
    pub fn gaussian_frame(
        &self,
        renderer: &GaussianRenderer,
        scene: &GpuGaussians,
        job: &FrameJob,
        plan: &Plan,
        load_ms: f64,
        events: &mut Events<'_>,
    ) -> Result<RenderedFrame> {
        let lens = self.gaussian_lens(&job.camera.aperture)?;
        let spec = job.camera.to_spec_in(plan.coordinates, plan.origin);
        events(JobEvent::Camera {
            number: job.number,
            spec: &spec,
        })?;
        let frame = match self.spec.method {
            Method::Layered(_) => {
                renderer.render_layered(scene, &job.camera, self.spec.background)?
            }
            _ => renderer.render(
                scene,
                &job.camera,
                &lens,
                self.gaussian_ssaa(),
                self.spec.background,
            )?,
        };
        let report = FrameReport {
            load_ms,
            counts: vec![
                (
                    crate::report::GAUSSIAN_TILE_ENTRIES.into(),
                    frame.entries as u64,
                ),
                ("gaussians.retries".into(), frame.retries as u64),
                (
                    crate::report::GAUSSIANS_IN_FRONT.into(),
                    scene.in_front(&job.camera) as u64,
                ),
            ],
            gaussians: true,
            ..FrameReport::new(
                &renderer.ctx().info,
                match self.spec.method {
                    // Its layers are depth layers, not --layers.
                    Method::Layered(_) => "layered".into(),
                    m => m.short_name(),
                },
                (job.camera.width, job.camera.height),
                self.gaussian_ssaa(),
                scene.len() as usize,
                frame.guard,
                &frame.timings,
                Default::default(),
            )
        };
        let output = job.output.clone();
        let write: FileWrite = match &self.video {
            Some(video) => {
                let video = video.clone();
                Box::new(move || video.push(&Srgb8Image::of(&frame.image)))
            }
            None => Box::new(move || write_image(&frame.image, &output)),
        };
        Ok(RenderedFrame {
            spec,
            report,
            write,
        })
    }

    /// The options of one frame through `camera`, its focus on what
    /// `--focus-pixel` sees.
    fn frame_options(
        &self,
        renderer: &Renderer,
        scene: &Scene,
        mut camera: Camera,
    ) -> Result<RenderOptions> {
        let s = &self.spec;
        let ssaa = renderer.ssaa(s.ssaa, s.samples_per_pass, &s.method)?;
        if let Some([x, y]) = s.focus_pixel {
            // The pinhole G-buffer's K, whatever the method (accum's
            // default K is its own): every method focuses alike.
            let probe = renderer.ssaa(s.ssaa, s.samples_per_pass, &Method::Pinhole)?;
            camera.focus_distance = renderer.depth_at_pixel(scene, &camera, probe, s.lod, x, y)?;
        }
        Ok(RenderOptions {
            camera,
            method: s.method,
            ssaa,
            samples_per_pass: s.samples_per_pass,
            background: s.background,
            lod: s.lod,
        })
    }

    /// Writes `reports` to `--timings-json` (if asked): one object for a
    /// single image, an array for a sequence.
    pub fn write_timings(&self, reports: &[FrameReport]) -> Result<()> {
        let Some(path) = &self.spec.timings_json else {
            return Ok(());
        };
        let text = match (self.is_sequence(), reports) {
            (false, [one]) => one.to_json(),
            _ => format!(
                "[\n{}\n]",
                reports
                    .iter()
                    .map(FrameReport::to_json)
                    .collect::<Vec<_>>()
                    .join(",\n")
            ),
        };
        write_text_atomically(path, &text)
    }
}

/// The cameras of `outcome` as a camera path (`--print-camera` of a
/// sequence).
pub fn camera_path(outcome: &Outcome) -> CameraPath {
    CameraPath::of_frames(outcome.cameras.iter().cloned())
}

/// Logs a written frame with the device's and the process's memory (a long
/// sequence shows whether either grows).
fn log_memory(ctx: &crate::vk::Context, job: &FrameJob, started: Instant) {
    let (rss, peak) = crate::report::host_memory_bytes().unwrap_or_default();
    log::info!(
        "frame {}: {} in {:.2} s (device memory {} B, host resident {} B, peak {} B)",
        job.number,
        job.output.display(),
        started.elapsed().as_secs_f64(),
        ctx.allocated_bytes(),
        rss,
        peak
    );
}

/// Handles SIGINT, SIGTERM and SIGHUP on a thread of their own. In a sequence the
/// first sets `stop`, and [`RenderJob::render`] ends after the frame in
/// flight; otherwise (a single image, or a second signal) the temporary
/// files of the writes in progress are removed and the process ends as the
/// signal's default action would (its status says which signal), so no
/// partial file, not even a hidden temporary, is left.
pub fn watch_signals(sequence: bool, stop: Arc<AtomicBool>) -> Result<()> {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    // SIGHUP too: an ssh session that closes ends its commands so.
    let mut signals =
        signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]).map_err(|source| {
            Error::System {
                what: "installing a signal handler",
                source,
            }
        })?;
    std::thread::spawn(move || {
        for signal in signals.forever() {
            if sequence && !stop.swap(true, Ordering::SeqCst) {
                continue;
            }
            let removed = crate::image_io::abandon_writes();
            log::debug!("signal {signal}: {removed} file(s) in writing removed");
            // Ends the process (terminate is these signals' default).
            let _ = signal_hook::low_level::emulate_default_handler(signal);
            std::process::exit(128 + signal);
        }
    });
    Ok(())
}

/// What one frame's render measured, before it becomes a [`FrameReport`].
struct FrameMeasure {
    rendered: Rendered<()>,
    camera: Camera,
}

impl FrameMeasure {
    fn into_report(
        self,
        renderer: &Renderer,
        spec: &JobSpec,
        options: &RenderOptions,
        scene: &Scene,
    ) -> FrameReport {
        let r = self.rendered;
        FrameReport {
            samples_per_pass: r.samples_per_pass,
            counts: r.counts.clone(),
            lod: r.lod,
            ..FrameReport::new(
                &renderer.ctx().info,
                spec.method.short_name(),
                (self.camera.width, self.camera.height),
                options.ssaa,
                scene.len(),
                r.guard,
                &r.timings,
                scene.upload,
            )
        }
    }
}

/// Renders one frame for the file `output`, and the write of that file
/// (atomic): PNG pixels encoded on the device (RGBA on the host when
/// transparent), EXR with R, G, B, A and the passes asked for.
fn render_frame(
    renderer: &Renderer,
    scene: &Scene,
    options: &RenderOptions,
    output: &Path,
    written: Written,
) -> Result<(FrameMeasure, FileWrite)> {
    let path = output.to_path_buf();
    let camera = options.camera;
    let (rendered, write): (Rendered<()>, FileWrite) = if !is_png_path(output)? {
        let Passes { z, coc } = written.passes;
        let (rendered, gbuffer) = match z || coc {
            true => {
                let (r, g) = renderer.render_with_gbuffer(scene, options)?;
                (r, Some(g))
            }
            false => (renderer.render(scene, options)?, None),
        };
        let (image, rendered) = split(rendered);
        let write = move || {
            let depth = gbuffer.map(|g| output_depths(&g, image.width, image.height));
            write_exr(&image, depth, &camera, &path, written)
        };
        (rendered, Box::new(write))
    } else if written.transparent {
        let (image, rendered) = split(renderer.render(scene, options)?);
        (rendered, Box::new(move || write_png_rgba(&image, &path)))
    } else {
        let (image, rendered) = split(renderer.render_srgb8(scene, options)?);
        (rendered, Box::new(move || image.write_png(&path)))
    };
    Ok((FrameMeasure { rendered, camera }, write))
}

/// Renders one frame of a video, and the write that appends it.
fn video_frame(
    renderer: &Renderer,
    scene: &Scene,
    options: &RenderOptions,
    video: &Arc<VideoSink>,
) -> Result<(FrameMeasure, FileWrite)> {
    let (image, rendered) = split(renderer.render_srgb8(scene, options)?);
    let video = video.clone();
    let write = Box::new(move || video.push(&image));
    Ok((
        FrameMeasure {
            rendered,
            camera: options.camera,
        },
        write,
    ))
}

/// A video output (`-o film.mp4`, `.webm`): ffmpeg started at the first
/// frame, at its size, fed every frame in order.
pub struct VideoSink {
    path: PathBuf,
    fps: u32,
    writer: std::sync::Mutex<Option<VideoWriter>>,
}

impl std::fmt::Debug for VideoSink {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        write!(f, "VideoSink({}, {} fps)", self.path.display(), self.fps)
    }
}

impl VideoSink {
    /// The video `spec` writes, if `-o` names one: checked before any
    /// cloud is read (a sequence, one file, opaque, no EXR passes, no
    /// `--skip-existing`, ffmpeg on PATH); `--fps` is refused without one.
    fn for_job(spec: &JobSpec) -> Result<Option<Arc<VideoSink>>> {
        let output = spec.output.display();
        if crate::video::Container::of(&spec.output).is_none() {
            if spec.fps.is_some() {
                return Err(invalid(format!(
                    "--fps is for a video output (-o film.mp4 or film.webm), not -o {output}"
                )));
            }
            return Ok(None);
        }
        let refuse = |why: &str| Err(invalid(format!("-o {output}: {why}")));
        if !spec.shot.is_sequence() {
            return refuse("a video needs a sequence (add --frames N or --path FILE)");
        }
        if FramePattern::parse(&spec.output)?.is_some() {
            return refuse("a video is one file: no frame number in its name");
        }
        if spec.skip_existing {
            return refuse("--skip-existing is for numbered frames, not a video");
        }
        if spec.written.transparent {
            return refuse(
                "a video has no alpha: a transparent background writes PNG or EXR frames",
            );
        }
        crate::video::ffmpeg(&spec.output)?;
        Ok(Some(Arc::new(VideoSink {
            path: FramePattern::single_image(&spec.output)?,
            fps: spec.fps.unwrap_or(crate::video::DEFAULT_FPS),
            writer: std::sync::Mutex::new(None),
        })))
    }

    /// Checks, before any frame renders, that the plan's frames are one
    /// size that the video takes.
    fn check_plan(&self, plan: &Plan) -> Result<()> {
        let Some(first) = plan.frames.first() else {
            return Ok(());
        };
        let size = (first.camera.width, first.camera.height);
        if let Some(other) = plan
            .frames
            .iter()
            .find(|f| (f.camera.width, f.camera.height) != size)
        {
            return Err(invalid(format!(
                "-o {}: frame {} is {}×{}, frame {} {}×{}: a video's frames are one size",
                self.path.display(),
                first.number,
                size.0,
                size.1,
                other.number,
                other.camera.width,
                other.camera.height
            )));
        }
        crate::video::check_size(&self.path, size.0, size.1)
    }

    /// Appends `frame`, starting ffmpeg at the first.
    fn push(&self, frame: &Srgb8Image) -> Result<()> {
        let mut writer = self.writer.lock().unwrap_or_else(|e| e.into_inner());
        if writer.is_none() {
            *writer = Some(VideoWriter::start(
                &self.path,
                frame.width,
                frame.height,
                self.fps,
            )?);
        }
        writer.as_mut().expect("started above").push(frame)
    }
}

/// A rendered frame's image, and the rest of it.
fn split<I>(rendered: Rendered<I>) -> (I, Rendered<()>) {
    let mut image = None;
    let rest = rendered.map(|i| image = Some(i));
    (image.expect("map takes the image"), rest)
}

/// Writes `image` as EXR: R, G, B, A (coverage when transparent, else 1),
/// and from the output pixels' eye `depth` the passes asked for.
fn write_exr(
    image: &LinearImage,
    depth: Option<Vec<f32>>,
    camera: &Camera,
    output: &Path,
    written: Written,
) -> Result<()> {
    let channel = |name: &str, samples: Vec<f32>| ExrChannel {
        name: name.to_string(),
        samples,
    };
    let component = |i: usize| image.pixels.iter().map(|p| p[i]).collect::<Vec<f32>>();
    let mut channels = vec![
        channel("R", component(0)),
        channel("G", component(1)),
        channel("B", component(2)),
        channel(
            "A",
            match written.transparent {
                true => component(3),
                false => vec![1.0; image.pixels.len()],
            },
        ),
    ];
    if let Some(depth) = depth {
        if written.passes.coc {
            channels.push(channel(
                "CoC",
                depth.iter().map(|&d| camera.coc_px(d)).collect(),
            ));
        }
        if written.passes.z {
            channels.push(channel("Z", depth));
        }
    }
    write_exr_channels(output, image.width, image.height, &channels)
}

/// The G-buffer's eye depth of each output pixel (guard band cropped).
fn output_depths(g: &HostGBuffer, width: u32, height: u32) -> Vec<f32> {
    let mut depth = Vec::with_capacity(width as usize * height as usize);
    for y in 0..height {
        let row = ((y + g.guard) * g.width + g.guard) as usize;
        depth.extend(g.eye[row..row + width as usize].iter().map(|e| e[2]));
    }
    depth
}

/// The most frames of a sequence rendered and not yet written while the
/// next renders ([`RenderJob::run`]): a writer thread encodes and writes
/// them in frame order as rendering goes on, each holding one frame's
/// pixels.
pub const WRITES_IN_FLIGHT: usize = 2;

/// The write of a frame's file, on any thread.
pub type FileWrite = Box<dyn FnOnce() -> Result<()> + Send>;

/// A frame rendered, its file not yet written.
pub struct RenderedFrame {
    /// Its camera as rendered, in the plan's coordinates.
    pub spec: CameraSpec,
    /// Its report (`encode_ms` set once its file is written).
    pub report: FrameReport,
    /// Writes its file.
    pub write: FileWrite,
}

/// `write`, and how long it took, ms.
fn timed_ms(write: FileWrite) -> Result<f64> {
    let started = Instant::now();
    write()?;
    Ok(started.elapsed().as_secs_f64() * 1e3)
}

/// The frames of [`RenderJob::run_frames`] whose files are written.
#[derive(Default)]
struct FilesWritten {
    outcome: Outcome,
    empty_frames: usize,
}

impl FilesWritten {
    /// Frame `job`'s write ended with `result` (None: not begun, after a
    /// signal): where its file is written, `events` is told so (and warned
    /// if the frame drew nothing of the scene).
    #[allow(clippy::too_many_arguments)]
    fn finish(
        &mut self,
        ctx: &crate::vk::Context,
        events: &mut Events<'_>,
        job: &FrameJob,
        started: Instant,
        spec: CameraSpec,
        mut report: FrameReport,
        result: Option<Result<f64>>,
    ) -> Result<()> {
        let Some(result) = result else {
            return Ok(());
        };
        report.encode_ms = result?;
        log_memory(ctx, job, started);
        if report.drew_nothing() {
            self.empty_frames += 1;
            if self.empty_frames == 1 {
                events(JobEvent::Warning(&empty_frame_warning(job.number, &report)))?;
            }
        }
        events(JobEvent::Written {
            number: job.number,
            output: &job.output,
            seconds: started.elapsed().as_secs_f64(),
            report: &report,
        })?;
        self.outcome.cameras.push((job.number, spec));
        self.outcome.reports.push(report);
        Ok(())
    }
}

/// The warning of the first frame that drew nothing of the scene.
fn empty_frame_warning(number: u32, report: &FrameReport) -> String {
    let in_front = report
        .counts
        .iter()
        .find(|(name, _)| name == crate::report::GAUSSIANS_IN_FRONT);
    if let Some((_, 0)) = in_front {
        return format!(
            "frame {number}: every Gaussian is behind the camera or nearer than the near plane \
             (1 % of the scene's extent, at most {} units): move the camera back",
            crate::gaussians::REFERENCE_NEAR_Z
        );
    }
    let what = match report.gaussians {
        true => "no Gaussian",
        false => "no point",
    };
    format!(
        "frame {number}: {what} of the scene is in view, only the background: check the \
         camera (a camera file's \"origin\" places it in the coordinates of the cloud it was \
         made for)"
    )
}

fn invalid(msg: impl Into<String>) -> Error {
    Error::InvalidArgument(msg.into())
}
