"""pointlens against Mitsuba 3: time and PSNR of the same splats through the
same thin lens (run by scripts/bench-vs-mitsuba, which sets up the Python
environment and the binaries; see that script for the options).

For each scene: pointlens prints its depth-of-field camera
(`render --print-camera`); examples/export_splats writes the splats (world
diameters and linear colors) that `render` draws; splat_scene.py turns them
into camera-facing emitting squares for Mitsuba. Then, alternating in every
round, pointlens renders each method (one process per frame, its frame wall
time from `--timings-json`) and Mitsuba renders each sample count (steady
render time, after a first render that includes the JIT). Every image is
compared with Mitsuba at the reference sample count by `pointlens compare`,
and each setting's G-buffer (the pinhole image of its K, coverage, raster
and level of detail; accum has none) with Mitsuba's pinhole image at the
reference's sample count.

With --aperture "FLAGS" (pointlens's aperture flags, e.g. "--aperture-blades
6 --aperture-rotation-deg 15"), the flags go to `--print-camera` and to
every pointlens render of a method, and the Mitsuba scene of the timed
renders and of the reference gets aperture_sensor.py's sensor built from the
printed camera (the same shape, by docs/decisions/aperture-shape.md) instead
of `thinlens`. A method that refuses the shape is skipped with a note. The
pinhole convention check and the max_depth check keep their sensors (a
pinhole has no aperture; max_depth does not depend on the lens).
"""

import argparse
import csv
import datetime
import json
import math
import os
import platform
import shlex
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import splat_scene as ss

# The pointlens flags --aperture may carry (docs/decisions/aperture-shape.md):
# the shape only, not the radius, which is the scene's.
APERTURE_FLAGS = ("--aperture-blades", "--aperture-rotation-deg", "--blade-curvature", "--anamorphic-ratio",
                  "--aperture-image", "--cat-eye")
# Their fields in the printed camera (aperture_sensor.APERTURE_FIELDS).
APERTURE_CAMERA_FIELDS = ("aperture_blades", "aperture_rotation_deg", "blade_curvature", "anamorphic_ratio",
                          "aperture_image", "cat_eye")

# The cameras: pointlens `render` flags; the rest of the camera is pointlens's
# default (auto-framing) and is read back with --print-camera.
SCENES = {
    # The Stanford bunny with its synthetic color checker (same points as
    # bun_zipper.ply, so the same splats): the default camera (auto-framed
    # from +z), focused on the nearest point (the chest, pixel 360,343),
    # R = 0.012: CoC 0 at the chest to 25 px at the back of the bunny.
    "bunny": {
        "file": "data/bunny_colored.ply",
        "flags": ["--aperture-radius", "0.012"],
        "focus_640x480": (360, 343),
        "accum": [16, 64],
    },
    # The same points, uncolored (gray): blur shows only at silhouettes.
    "bun_zipper": {
        "file": "data/bun_zipper.ply",
        "flags": ["--aperture-radius", "0.012"],
        "focus_640x480": (360, 343),
        "accum": [16, 64],
    },
    # The PCL stereo scan from its sensor (as `bench`'s mug), focused on the
    # mug (pixel 380,330), R = 0.015: the back wall blurs to 29 px.
    "mug": {
        "file": "data/pcl_table_scene_mug_rgb.ply",
        "flags": [
            "--eye", "0,0,0", "--target", "0,0,1", "--up", "0,-1,0", "--fovy-deg", "27.95",
            "--aperture-radius", "0.015",
        ],
        "focus_640x480": (380, 330),
        # accum 64 takes about 2 minutes here on 2 cores (lavapipe).
        "accum": [16],
    },
    # The bundled LiDAR tile (aerial, z up) in a tilt-shift view: an
    # oblique camera over the tile, focused on the middle of the frame,
    # R = 10 ft, so the near field and the far edge blur and a band across
    # the middle is sharp.
    "autzen": {
        "file": "data/autzen_trim.las",
        "flags": [
            "--eye", "0,-520,300", "--target", "0,80,-20", "--up", "0,0,1", "--fovy-deg", "45",
            "--aperture-radius", "10",
        ],
        "focus_640x480": (320, 240),
        "accum": [16],
    },
}


class Failure(Exception):
    """A one-line error for the user."""


def fail(msg):
    raise Failure(msg)


def log(msg):
    print(f"[bench-vs-mitsuba] {msg}", file=sys.stderr, flush=True)


def run(cmd, what):
    """Runs a command; its stdout, or a Failure naming `what` with the last
    line of its stderr."""
    proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["(no message)"])[-1]
        fail(f"{what} failed (exit {proc.returncode}): {last}")
    return proc.stdout


def parse_list(text, name, cast=int):
    try:
        values = [cast(v) for v in text.split(",") if v.strip()]
    except ValueError:
        fail(f"{name}: not a list of numbers: {text}")
    if not values or any(v <= 0 for v in values):
        fail(f"{name}: needs positive numbers, got {text}")
    return values


def parse_args(argv):
    p = argparse.ArgumentParser(prog="bench-vs-mitsuba", add_help=True)
    p.add_argument("--pointlens", required=True)
    p.add_argument("--export-splats", required=True)
    p.add_argument("--repo", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--work", required=True)
    p.add_argument("--scenes", default="bunny,mug")
    p.add_argument("--reps", type=int, default=3)
    p.add_argument("--spp", default="1,2,4,8,16,32,64,128")
    p.add_argument("--ref-spp", type=int, default=1024)
    p.add_argument("--accum", default=None)
    p.add_argument("--repeat-limit-s", type=float, default=15.0)
    p.add_argument("--pinhole-spp", type=int, default=128)
    p.add_argument("--variant", default="llvm_ad_rgb")
    p.add_argument("--device", default=None)
    p.add_argument("--label", default=None)
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=480)
    p.add_argument("--raster", default=None, choices=["sprites", "compute"])
    p.add_argument("--lod-px", type=float, default=None)
    p.add_argument("--splat-shape", default="square", choices=["square", "disc"])
    p.add_argument("--ssaa", default=None)
    p.add_argument("--coverage", default=None)
    p.add_argument("--methods", default=None)
    p.add_argument("--aperture", default=None,
                   help="pointlens aperture flags, one string (e.g. \"--aperture-blades 6\"): to "
                        "--print-camera and every method's render; Mitsuba samples the same shape")
    p.add_argument("--warm-cold", action="store_true",
                   help="also time pointlens warm (the steady frames of a 12-frame sequence of one "
                        "camera) and cold (a whole one-frame process), against Mitsuba's steady and "
                        "first (JIT) renders, and print both ratios")
    try:
        args = p.parse_args(argv)
    except SystemExit as e:
        raise Failure("bad arguments (see the usage above)") if e.code else e
    args.scenes = [s for s in args.scenes.split(",") if s]
    for s in args.scenes:
        if s not in SCENES:
            fail(f"--scenes: unknown scene '{s}' (known: {', '.join(SCENES)})")
    args.spp = sorted(set(parse_list(args.spp, "--spp")))
    args.accum = sorted(set(parse_list(args.accum, "--accum"))) if args.accum else None
    args.ssaa = parse_list(args.ssaa, "--ssaa") if args.ssaa else None
    args.coverage = args.coverage.split(",") if args.coverage else None
    if args.coverage and (set(args.coverage) - {"area", "samples"} or len(set(args.coverage)) != len(args.coverage)):
        fail("--coverage: distinct values of area and samples, as pointlens takes them")
    if args.ssaa and (max(args.ssaa) > 16 or len(set(args.ssaa)) != len(args.ssaa)):
        fail("--ssaa: distinct values from 1 to 16, as pointlens takes them")
    if not args.scenes:
        fail("--scenes: no scene given")
    if args.reps < 1:
        fail("--reps must be at least 1")
    if not (16 <= args.width <= 8192 and 16 <= args.height <= 8192):
        fail("--width and --height must be 16 to 8192")
    args.aperture_flags = parse_aperture(args.aperture) if args.aperture is not None else []
    if args.ref_spp < 1 or args.pinhole_spp < 1:
        fail("--ref-spp and --pinhole-spp must be positive")
    for name, n in [("--spp", v) for v in args.spp] + [("--ref-spp", args.ref_spp),
                                                        ("--pinhole-spp", args.pinhole_spp)]:
        if n > 64 and n % 64:
            fail(f"{name}: sample counts above 64 must be multiples of 64 (rendered in passes of 64), got {n}")
    return args


def parse_aperture(text):
    """--aperture's string as pointlens arguments: only the shape's flags
    (APERTURE_FLAGS), each with its value (as FLAG VALUE or FLAG=VALUE);
    an aperture image made absolute (the printed camera keeps the path as
    given, and pointlens reads a camera file's relative path from the file's
    folder, which here is the work folder)."""
    try:
        words = shlex.split(text)
    except ValueError as e:
        fail(f"--aperture: {e}")
    if not words:
        fail("--aperture: no flags given (e.g. --aperture \"--aperture-blades 6\")")
    out = []
    k = 0
    while k < len(words):
        flag, eq, value = words[k].partition("=")
        if flag not in APERTURE_FLAGS:
            fail(f"--aperture: '{words[k]}' is not one of {', '.join(APERTURE_FLAGS)}")
        if not eq:
            if k + 1 >= len(words):
                fail(f"--aperture: {flag} needs a value")
            value = words[k + 1]
            k += 1
        k += 1
        if flag == "--aperture-image":
            value = os.path.abspath(value)
            if not os.path.isfile(value):
                fail(f"--aperture: no aperture image at {value}")
        out += [flag, value]
    return out


def methods(args, scene):
    """pointlens methods: (name as `bench` names it, render flags); accum's
    sample counts from --accum, else the scene's. With --ssaa, each method
    at each K, named with `-ssaaK`; with --coverage, each at each
    coverage, named with `-area` or `-samples` (accum by samples only)."""
    m = [("pinhole", ["--method", "pinhole"]), ("fast", ["--method", "fast"]),
         ("fast-tree", ["--method", "fast", "--fast-gather", "tree"]),
         ("rdb9", ["--method", "rdb", "--rdb-bins", "9"]),
         ("layered1", ["--method", "layered", "--layers", "1"]),
         ("layered2", ["--method", "layered", "--layers", "2"]),
         ("layered4", ["--method", "layered", "--layers", "4"])]
    m += [(f"accum{s}", ["--method", "accum", "--samples", str(s)]) for s in args.accum or SCENES[scene]["accum"]]
    if args.methods:
        wanted = args.methods.split(",")
        unknown = [w for w in wanted if w not in [name for name, _ in m]]
        if unknown:
            fail(f"--methods: unknown {', '.join(unknown)} (known: {', '.join(name for name, _ in m)})")
        m = [(name, flags) for name, flags in m if name in wanted]
    raster = ["--raster", args.raster] if args.raster else []
    # --lod-px 0: every splat, as Mitsuba draws them.
    raster += ["--lod-px", f"{args.lod_px:g}"] if args.lod_px is not None else []
    if args.coverage:
        # accum refuses area (a G-buffer per lens position): its samples only.
        m = [(f"{name}-{c}", flags + ["--coverage", c]) for c in args.coverage for name, flags in m
             if c == "samples" or not name.startswith("accum")]
    if not args.ssaa:
        return [(name, flags + raster) for name, flags in m]
    return [(f"{name}-ssaa{k}", flags + raster + ["--ssaa", str(k)]) for k in args.ssaa for name, flags in m]


def gbuffer_flags(flags):
    """The flags of a setting that make its G-buffer (K, coverage, raster,
    level of detail), to render it as a pinhole image; None for accum,
    whose lens positions each take a G-buffer of their own."""
    if flags[flags.index("--method") + 1] == "accum":
        return None
    out = []
    for k, flag in enumerate(flags):
        if flag in ("--ssaa", "--coverage", "--raster", "--lod-px"):
            out += [flag, flags[k + 1]]
    return out


def scene_flags(args, scene):
    """The scene's camera flags at the run's size: its focus pixel, given
    at 640×480, scaled to the frame (pointlens fails with a clear line if
    it sees no point there)."""
    fx, fy = SCENES[scene]["focus_640x480"]
    focus = f"{fx * args.width // 640},{fy * args.height // 480}"
    return ["--width", str(args.width), "--height", str(args.height), *SCENES[scene]["flags"],
            "--focus-pixel", focus]


class Bench:
    def __init__(self, args):
        self.args = args
        self.repo = Path(args.repo)
        self.work = Path(args.work)
        self.out = Path(args.out)
        import drjit as dr
        import mitsuba as mi

        try:
            mi.set_variant(args.variant)
        except Exception as e:  # noqa: BLE001 - Mitsuba raises plain errors
            fail(f"Mitsuba variant {args.variant} is not usable here: {e}")
        self.mi, self.dr = mi, dr
        self.aperture_sensor = None
        if args.aperture_flags:
            import aperture_sensor

            try:
                aperture_sensor.register()
            except RuntimeError as e:
                fail(f"--aperture: {e}")
            self.aperture_sensor = aperture_sensor
        self.cache_dir = os.environ.get("DRJIT_CACHE_DIR")
        self.results = {"scenes": {}}

    # -- pointlens ---------------------------------------------------------

    def pointlens(self, *argv, what):
        cmd = [self.args.pointlens, *argv]
        return run(cmd, what)

    def device_flags(self):
        return ["--device", self.args.device] if self.args.device else []

    def render_pointlens(self, scene, name, flags, out_exr, camera, aperture=True, warm=True):
        """A pointlens frame; with --aperture, its flags after the method's
        unless `aperture` is False (the pinhole check); with --warm-cold,
        its steady frames too unless `warm` is False."""
        flags = flags + (self.args.aperture_flags if aperture else [])
        tj = out_exr.with_suffix(".timings.json")
        started = time.perf_counter()
        self.pointlens("render", str(self.repo / SCENES[scene]["file"]), "-o", str(out_exr),
                       "--camera", str(camera), "--splat-shape", self.args.splat_shape, *flags,
                       *self.device_flags(), "--timings-json", str(tj),
                       what=f"pointlens render ({scene}, {name})")
        process_s = time.perf_counter() - started
        t = json.loads(tj.read_text())
        steady = None
        if self.args.warm_cold and warm:
            # The same camera twelve times in one process: frames 9-12 are
            # steady: pipelines and scene warm, and the host's image
            # buffers reused (on an H200's host a 1080p EXR frame's
            # readback copy took 22-29 ms in the first six frames and
            # 9-12 ms after, with one thread).
            tw = out_exr.with_suffix(".warm.json")
            pattern = out_exr.with_name(out_exr.stem + "_warm_%d.exr")
            self.pointlens("render", str(self.repo / SCENES[scene]["file"]), "-o", str(pattern),
                           "--camera", str(camera), "--splat-shape", self.args.splat_shape, *flags,
                           *self.device_flags(), "--frames", "12", "--orbit", "0",
                           "--timings-json", str(tw), what=f"pointlens warm ({scene}, {name})")
            frames = json.loads(tw.read_text())
            steady = statistics.median(f["frame_wall_ms"] for f in frames[8:])
        return {
            "steady_ms": steady,
            "frame_wall_ms": t["frame_wall_ms"],
            "gpu_total_ms": t["gpu_total_ms"],
            "upload_wall_ms": t["upload"]["wall_ms"],
            "splat_sizes_ms": t["upload"].get("splat_sizes_ms", 0.0),
            "load_ms": t["load_ms"],
            "encode_ms": t["encode_ms"],
            "process_ms": process_s * 1e3,
            "device": t["device"],
            "guard_px": t["guard_px"],
        }

    def compare(self, a, b):
        out = self.pointlens("compare", str(a), str(b), what=f"pointlens compare {a.name} {b.name}")
        vals = {}
        for line in out.splitlines():
            k, _, v = line.partition(":")
            vals[k.strip()] = float(v)
        if "psnr" not in vals:
            fail(f"pointlens compare printed no psnr for {a} {b}")
        return vals

    # -- Mitsuba -----------------------------------------------------------

    def cold_jit(self):
        """Makes the next render compile its kernels again: Dr.Jit's kernel
        cache is emptied in memory and on disk (the wrapper points
        DRJIT_CACHE_DIR at a folder of this run)."""
        self.dr.flush_kernel_cache()
        if self.cache_dir and Path(self.cache_dir).is_dir():
            for f in Path(self.cache_dir).iterdir():
                if f.is_file():
                    f.unlink()

    def mitsuba_render(self, scene, spp, seed):
        # One pass holds W·H·spp samples; above 64 spp render passes of
        # 64 spp with distinct seeds and average them (memory).
        if spp <= 64:
            return ss.render(self.mi, self.dr, scene, spp, seed)
        if spp % 64:
            fail(f"sample counts above 64 must be multiples of 64, got {spp}")
        total, seconds = None, 0.0
        for k in range(spp // 64):
            img, s = ss.render(self.mi, self.dr, scene, 64, seed * 7919 + k)
            total = img if total is None else total + img
            seconds += s
        return total / (spp // 64), seconds

    # -- the steps ---------------------------------------------------------

    def prepare(self, scene):
        """Camera, splats, pinhole check, Mitsuba scene."""
        a = self.args
        d = self.work / scene
        d.mkdir(parents=True, exist_ok=True)
        ply = self.repo / SCENES[scene]["file"]
        # The DOF camera, as pointlens resolves it (auto-framing, --focus-pixel);
        # with --aperture, its shape too (printed by a method that takes one:
        # pinhole refuses a shape).
        probe = ["--method", "accum", *a.aperture_flags] if a.aperture_flags else ["--method", "pinhole"]
        cam_text = self.pointlens("render", str(ply), "-o", str(d / "camera_probe.exr"), *probe,
                                  *scene_flags(a, scene), *self.device_flags(), "--print-camera",
                                  what=f"pointlens --print-camera ({scene})")
        try:
            cam = json.loads(cam_text)
        except json.JSONDecodeError:
            fail(f"pointlens --print-camera ({scene}) printed no JSON camera")
        (d / "camera.json").write_text(json.dumps(cam, indent=2))
        pin = dict(cam, aperture_radius=0.0)
        # A pinhole has no aperture (and pointlens's pinhole refuses a shape).
        for key in APERTURE_CAMERA_FIELDS:
            pin.pop(key, None)
        (d / "camera_pinhole.json").write_text(json.dumps(pin, indent=2))

        splats = d / "splats.bin"
        run([a.export_splats, str(ply), str(splats)], f"export_splats ({scene})")
        try:
            positions, diameters, colors = ss.read_splats(splats)
        except ValueError as e:
            fail(str(e))

        info = {"camera": cam, "points": int(len(positions)),
                "diameter_median": float(np.median(diameters)), "file": SCENES[scene]["file"]}
        eye, right, up, forward = ss.camera_basis(cam)
        z = (positions.astype(np.float64) - eye) @ forward
        fpx = ss.f_px(cam)
        coc = 2 * cam["aperture_radius"] * fpx * np.abs(z - cam["focus_distance"]) / (z * cam["focus_distance"])
        info["coc_px_max"] = float(coc.max())
        info["coc_px_background"] = float(2 * cam["aperture_radius"] * fpx / cam["focus_distance"])
        info["splat_px_median"] = float(np.median(fpx * diameters / z))

        # Convention check: pinhole pointlens against a pinhole Mitsuba.
        log(f"{scene}: pinhole convention check ({a.pinhole_spp} spp)")
        pl_pin = d / "pointlens_pinhole_check.exr"
        # Every point (--lod-px 0): the splats Mitsuba draws, so that what is
        # left is the conventions (the methods below run as users run them,
        # at the default level of detail).
        self.render_pointlens(scene, "pinhole", ["--method", "pinhole", "--lod-px", "0"], pl_pin,
                              d / "camera_pinhole.json", aperture=False, warm=False)
        mscene, minfo = ss.build_scene(self.mi, pin, positions, diameters, colors, shape=a.splat_shape)
        img, _ = self.mitsuba_render(mscene, a.pinhole_spp, 7)
        mi_pin = d / "mitsuba_pinhole_check.exr"
        ss.write_exr(self.mi, mi_pin, img)
        check = self.compare(pl_pin, mi_pin)
        check.update(alignment(read_exr(self.mi, pl_pin), img))
        check["squares"] = minfo
        # The two emulations of pointlens's rasteriser, each left out once
        # for the record where it moves at least 0.1 % of the squares: the
        # 1-pixel sprite minimum and the tie order.
        for key, extra in (("psnr_without_1px_minimum", {"min_px": 0.0}),
                           ("psnr_without_tie_order", {"ties": False})):
            changed = minfo["enlarged_to_min_px"] if "min_px" in extra else minfo["tie_points_moved"]
            if changed >= 0.001 * len(positions):
                raw, _ = ss.build_scene(self.mi, pin, positions, diameters, colors, shape=a.splat_shape,
                                        **extra)
                img, _ = self.mitsuba_render(raw, a.pinhole_spp, 7)
                ss.write_exr(self.mi, d / "mitsuba_pinhole_variant.exr", img)
                check[key] = self.compare(pl_pin, d / "mitsuba_pinhole_variant.exr")["psnr"]
                del raw
        # What is left is pointlens's anti-aliasing (K×K point samples per
        # pixel against Mitsuba's area integral): it shrinks with K.
        pl_pin8 = d / "pointlens_pinhole_check_ssaa8.exr"
        self.render_pointlens(scene, "pinhole", ["--method", "pinhole", "--ssaa", "8", "--lod-px", "0"], pl_pin8,
                              d / "camera_pinhole.json", aperture=False, warm=False)
        check["psnr_pointlens_ssaa8"] = self.compare(pl_pin8, mi_pin)["psnr"]
        info["pinhole_check"] = check
        del mscene

        self.cold_jit()
        mscene, minfo = self.build_dof_scene(cam, positions, diameters, colors)
        info["mitsuba_build_ms"] = minfo["build_s"] * 1e3
        info["squares"] = minfo
        return d, info, mscene, (positions, diameters, colors)

    def pinhole_reference(self, scene):
        """Mitsuba's pinhole image of the scene's splats at the reference's
        sample count (what the G-buffers are measured against)."""
        a = self.args
        d, _, _, (positions, diameters, colors) = self.prepared[scene]
        log(f"{scene}: Mitsuba pinhole reference, {a.ref_spp} spp")
        pin = json.loads((d / "camera_pinhole.json").read_text())
        mscene, _ = ss.build_scene(self.mi, pin, positions, diameters, colors, shape=a.splat_shape)
        img, _ = self.mitsuba_render(mscene, a.ref_spp, 1000)
        out = d / f"mitsuba_pinhole_{a.ref_spp}spp.exr"
        ss.write_exr(self.mi, out, img)
        return out

    def build_dof_scene(self, cam, positions, diameters, colors):
        """The Mitsuba scene of the timed renders and the reference:
        splat_scene's, whose sensor is `thinlens`, or with --aperture
        aperture_sensor's sensor of the printed camera (its film
        splat_scene's)."""
        sensor = None
        if self.aperture_sensor is not None:
            film = ss.sensor_dict(self.mi, cam)["film"]
            sensor = self.aperture_sensor.sensor_from_camera(cam, film)
        return ss.build_scene(self.mi, cam, positions, diameters, colors, shape=self.args.splat_shape,
                              sensor=sensor)

    def refused(self, scene, meths):
        """With --aperture: the methods whose render refuses the shape
        ({name: pointlens's line}), found by `--print-camera` with the
        method's flags at 32×24 (it checks the method against the camera
        before rendering; the frame it renders then is small)."""
        if not self.args.aperture_flags:
            return {}
        d = self.work / scene
        out = {}
        for name, flags in meths:
            cmd = [self.args.pointlens, "render", str(self.repo / SCENES[scene]["file"]),
                   "-o", str(d / "camera_probe.exr"), "--camera", str(d / "camera.json"),
                   "--splat-shape", self.args.splat_shape, *flags, *self.args.aperture_flags,
                   *self.device_flags(), "--width", "32", "--height", "24", "--print-camera"]
            proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            if proc.returncode != 0:
                out[name] = (proc.stderr.strip().splitlines() or ["(no message)"])[-1]
                log(f"{scene}: skipping {name}, which refuses the aperture: {out[name]}")
        return out

    def max_depth_check(self, cam, splats):
        """What Mitsuba's max_depth means, by rendering: the benchmark scene
        at max_depth 0, 1, 2 (mean pixel value), and a probe scene with a
        gray diffuse wall, a square lamp facing the wall (its unlit back to
        the camera) and a small square lamp facing the camera: the mean
        value of the lamp seen directly and of the wall lit by the other."""
        mi = self.mi
        out = {}
        for md in (0, 1, 2):
            scene, _ = ss.build_scene(mi, cam, *splats, max_depth=md, shape=self.args.splat_shape)
            img, _ = ss.render(mi, self.dr, scene, 8, 3)
            out[f"scene_max_depth_{md}"] = float(img.mean())

        def square(z, half, normal_z, cx=0.0, cy=0.0, emit=None, reflect=None):
            # A rectangle's default normal is +z; flip it to face -z.
            t = mi.ScalarTransform4f().translate([cx, cy, z]) @ mi.ScalarTransform4f().scale([half, half, 1.0])
            if normal_z < 0:
                t = t @ mi.ScalarTransform4f().rotate([1, 0, 0], 180)
            d = {"type": "rectangle", "to_world": t}
            if emit is not None:
                d["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": emit}}
                d["bsdf"] = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}
            else:
                d["bsdf"] = {"type": "diffuse", "reflectance": {"type": "rgb", "value": reflect}}
            return d

        probe_cam = {"width": 64, "height": 64, "eye": [0, 0, 0], "target": [0, 0, 1], "up": [0, 1, 0],
                     "fovy_deg": 40.0, "aperture_radius": 0.0, "focus_distance": 1.0}
        for md in (0, 1, 2):
            scene = mi.load_dict({
                "type": "scene",
                "integrator": {"type": "path", "max_depth": md},
                "sensor": ss.sensor_dict(mi, probe_cam),
                # The wall at z = 3 facing the camera, a lamp at z = 1.5 facing
                # the wall (its back, one-sided, to the camera), and a small
                # lamp at z = 1 facing the camera, off to the side.
                "wall": square(3.0, 2.0, -1, reflect=[0.5, 0.5, 0.5]),
                "lamp": square(1.5, 0.15, +1, emit=[10.0, 10.0, 10.0]),
                "seen": square(1.0, 0.05, -1, cx=0.25, cy=0.25, emit=[1.0, 1.0, 1.0]),
            })
            img, _ = ss.render(mi, self.dr, scene, 16, 3)
            # The small lamp at (0.25, 0.25, 1) covers pixels 5.6–14.4 in x and y (upper
            # left: x = +0.25 is the camera's left here); the wall's corner
            # region at the lower right sees neither lamp.
            out[f"probe_max_depth_{md}_lamp_seen"] = float(img[7:13, 7:13].mean())
            out[f"probe_max_depth_{md}_wall"] = float(img[48:58, 48:58].mean())
        return out

    def main(self):
        a = self.args
        self.work.mkdir(parents=True, exist_ok=True)
        self.out.mkdir(parents=True, exist_ok=True)
        prepared = self.prepared = {}
        for scene in a.scenes:
            prepared[scene] = self.prepare(scene)
        first = prepared[a.scenes[0]]
        log("max_depth check")
        self.results["max_depth_check"] = self.max_depth_check(first[1]["camera"], first[3])

        meths = {s: methods(a, s) for s in a.scenes}
        if a.aperture_flags:
            skipped = {s: self.refused(s, meths[s]) for s in a.scenes}
            for s in a.scenes:
                meths[s] = [(name, flags) for name, flags in meths[s] if name not in skipped[s]]
                if not meths[s]:
                    fail(f"{s}: every method refuses --aperture '{a.aperture}' "
                         f"({'; '.join(sorted(set(skipped[s].values())))})")
            self.results["aperture"] = {"flags": a.aperture_flags, "skipped": skipped}
        pl = {s: {m: [] for m, _ in meths[s]} for s in a.scenes}
        mt = {s: {spp: [] for spp in a.spp} for s in a.scenes}
        mt_first = {s: {} for s in a.scenes}
        load = []
        for r in range(a.reps):
            for scene in a.scenes:
                d, info, mscene, _ = prepared[scene]
                # pointlens frames and Mitsuba renders in turn, one of each
                # after the other, so that both see the same load.
                jobs_pl = [(name, flags) for name, flags in meths[scene]
                           if not (pl[scene][name]
                                   and pl[scene][name][0]["frame_wall_ms"] > a.repeat_limit_s * 1e3)]
                jobs_mi = [spp for spp in a.spp
                           if not (mt[scene][spp] and mt[scene][spp][0] > a.repeat_limit_s * 1e3)]
                jobs = []
                for k in range(max(len(jobs_pl), len(jobs_mi))):
                    if k < len(jobs_pl):
                        jobs.append(("pointlens", jobs_pl[k]))
                    if k < len(jobs_mi):
                        jobs.append(("mitsuba", jobs_mi[k]))
                load.append(os.getloadavg()[0])
                for kind, job in jobs:
                    if kind == "pointlens":
                        name, flags = job
                        log(f"round {r + 1}/{a.reps} {scene}: pointlens {name}")
                        pl[scene][name].append(self.render_pointlens(scene, name, flags, d / f"pointlens_{name}.exr",
                                                                     d / "camera.json"))
                        continue
                    spp = job
                    log(f"round {r + 1}/{a.reps} {scene}: Mitsuba {spp} spp")
                    if r == 0:
                        # What one run of Mitsuba at this sample count pays:
                        # the kernels compiled from scratch.
                        self.cold_jit()
                        img, s = self.mitsuba_render(mscene, spp, 0)
                        mt_first[scene][spp] = s * 1e3
                        ss.write_exr(self.mi, d / f"mitsuba_{spp}spp.exr", img)
                    _, s = self.mitsuba_render(mscene, spp, 0)
                    mt[scene][spp].append(s * 1e3)
        load.append(os.getloadavg()[0])
        self.results["load_average_1min"] = load

        for scene in a.scenes:
            d, info, mscene, _ = prepared[scene]
            log(f"{scene}: Mitsuba reference, {a.ref_spp} spp")
            img, s = self.mitsuba_render(mscene, a.ref_spp, 1000)
            ref = d / f"mitsuba_ref_{a.ref_spp}spp.exr"
            ss.write_exr(self.mi, ref, img)
            info["reference_render_ms"] = s * 1e3
            rows = []
            gbuffers = {}
            pin_ref = None
            for name, flags in meths[scene]:
                runs = pl[scene][name]
                q = self.compare(d / f"pointlens_{name}.exr", ref)
                # Its G-buffer as a pinhole image against Mitsuba's pinhole
                # image at the reference's sample count: one per set of
                # G-buffer flags, shared by the methods that give the same.
                g = gbuffer_flags(flags)
                if g is not None and tuple(g) not in gbuffers:
                    if pin_ref is None:
                        pin_ref = self.pinhole_reference(scene)
                    out = d / f"pointlens_gbuffer_{len(gbuffers)}.exr"
                    self.render_pointlens(scene, f"G-buffer of {name}", ["--method", "pinhole", *g], out,
                                          d / "camera_pinhole.json", aperture=False, warm=False)
                    gbuffers[tuple(g)] = self.compare(out, pin_ref)["psnr"]
                ms = [x["frame_wall_ms"] for x in runs]
                rows.append({"renderer": "pointlens", "setting": name, "psnr": q["psnr"], "ssim": q["ssim"],
                             "gbuffer_psnr": gbuffers[tuple(g)] if g is not None else None,
                             "time_ms": statistics.median(ms), "time_min_ms": min(ms), "time_max_ms": max(ms),
                             "n": len(ms), "first_ms": None,
                             "gpu_total_ms": statistics.median(x["gpu_total_ms"] for x in runs),
                             "process_ms": statistics.median(x["process_ms"] for x in runs),
                             "steady_ms": (statistics.median(x["steady_ms"] for x in runs)
                                           if a.warm_cold else None),
                             "load_ms": statistics.median(x["load_ms"] for x in runs),
                             "splat_sizes_ms": statistics.median(x["splat_sizes_ms"] for x in runs),
                             "upload_wall_ms": statistics.median(x["upload_wall_ms"] for x in runs),
                             "runs": runs})
            for spp in a.spp:
                q = self.compare(d / f"mitsuba_{spp}spp.exr", ref)
                ms = mt[scene][spp]
                rows.append({"renderer": "mitsuba", "setting": f"{spp} spp", "spp": spp, "psnr": q["psnr"],
                             "ssim": q["ssim"], "time_ms": statistics.median(ms), "time_min_ms": min(ms),
                             "time_max_ms": max(ms), "n": len(ms), "first_ms": mt_first[scene][spp],
                             "runs_ms": ms})
            curve = [(r["spp"], r["psnr"], r["time_ms"]) for r in rows if r["renderer"] == "mitsuba"]
            cold = [(r["spp"], r["psnr"], r["first_ms"]) for r in rows
                    if r["renderer"] == "mitsuba" and r["first_ms"]]
            for r in rows:
                if r["renderer"] == "pointlens":
                    eq = equal_quality(curve, r["psnr"])
                    r.update(eq)
                    r["ratio"] = eq["mitsuba_ms_same_psnr"] / r["time_ms"] if eq["mitsuba_ms_same_psnr"] else None
                    if a.warm_cold:
                        # Warm: both renderers' steady frames; cold: a whole
                        # one-frame pointlens process against Mitsuba's first
                        # render at the same PSNR (its kernels compiled).
                        mw = eq["mitsuba_ms_same_psnr"]
                        mc = equal_quality(cold, r["psnr"])["mitsuba_ms_same_psnr"]
                        r["ratio_warm"] = mw / r["steady_ms"] if mw and r["steady_ms"] else None
                        r["ratio_cold"] = mc / r["process_ms"] if mc else None
            info["rows"] = rows
            info["pointlens_device"] = next(iter(pl[scene].values()))[0]["device"]
            self.results["scenes"][scene] = info
        self.finish()

    def finish(self):
        a = self.args
        env = environment(a, self.mi, self.dr, self.results)
        self.results["environment"] = env
        (self.out / "results.json").write_text(json.dumps(self.results, indent=2) + "\n")
        write_csv(self.out / "results.csv", self.results)
        chart(self.out / "time_vs_psnr.png", self.results)
        print(markdown(self.results))
        log(f"wrote {self.out}/results.json, results.csv, time_vs_psnr.png")


def read_exr(mi, path):
    return np.array(mi.Bitmap(str(path)), dtype=np.float32)[..., :3]


def srgb(x):
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def psnr_np(a, b):
    m = float(np.mean((srgb(a) - srgb(b)) ** 2))
    return math.inf if m == 0 else 10 * math.log10(1 / m)


def alignment(pl, mi_img):
    """Evidence for the pixel conventions: the PSNR (sRGB, as `compare`)
    of the Mitsuba image as is, flipped, and shifted by one pixel; and the
    difference of the two images' luminance centroids in pixels (a
    half-pixel convention error would show as 0.5)."""
    out = {"psnr_as_is": psnr_np(pl, mi_img),
           "psnr_flipped_y": psnr_np(pl, mi_img[::-1]),
           "psnr_flipped_x": psnr_np(pl, mi_img[:, ::-1])}
    best = max((psnr_np(pl[1:-1, 1:-1], np.roll(mi_img, (dy, dx), (0, 1))[1:-1, 1:-1]), dx, dy)
               for dx in (-1, 0, 1) for dy in (-1, 0, 1))
    out["best_integer_shift"] = {"psnr": best[0], "dx": best[1], "dy": best[2]}

    def centroid(img):
        w = img.mean(axis=2)
        ys, xs = np.mgrid[0:img.shape[0], 0:img.shape[1]]
        return float((w * xs).sum() / w.sum()), float((w * ys).sum() / w.sum())

    (ax, ay), (bx, by) = centroid(pl), centroid(mi_img)
    out["centroid_offset_px"] = {"dx": bx - ax, "dy": by - ay}
    return out


def equal_quality(curve, p):
    """The Mitsuba sample count and steady render time at PSNR p, by linear
    interpolation of PSNR in log2(spp) and of log(time) in log2(spp) along
    the Mitsuba curve; beyond its ends, the last segment's slope
    (extrapolated, marked)."""
    curve = sorted(curve)
    if len(curve) < 2:
        return {"mitsuba_spp_same_psnr": None, "mitsuba_ms_same_psnr": None, "same_psnr_note": "no curve"}
    xs = [math.log2(c[0]) for c in curve]
    ps = [c[1] for c in curve]
    ts = [math.log(c[2]) for c in curve]
    note = ""
    if p < ps[0]:
        i, note = 0, "below 1 spp (extrapolated)"
    elif p > ps[-1]:
        i, note = len(curve) - 2, f"above {curve[-1][0]} spp (extrapolated)"
    else:
        i = next(k for k in range(len(curve) - 1) if ps[k] <= p <= ps[k + 1] or k == len(curve) - 2)
        # A noisy, non-monotonic curve: the first bracketing segment.
        for k in range(len(curve) - 1):
            if min(ps[k], ps[k + 1]) <= p <= max(ps[k], ps[k + 1]):
                i = k
                break
    dp = ps[i + 1] - ps[i]
    f = (p - ps[i]) / dp if dp != 0 else 0.0
    x = xs[i] + f * (xs[i + 1] - xs[i])
    t = ts[i] + (x - xs[i]) * (ts[i + 1] - ts[i]) / (xs[i + 1] - xs[i])
    return {"mitsuba_spp_same_psnr": 2 ** x, "mitsuba_ms_same_psnr": math.exp(t), "same_psnr_note": note}


def cpu_model():
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def environment(a, mi, dr, results):
    scenes = results["scenes"]
    dev = next(iter(scenes.values()))["pointlens_device"] if scenes else {}
    env = {
        "date": datetime.date.today().isoformat(),
        "cpu": cpu_model(),
        "cpu_count": os.cpu_count(),
        "pointlens_binary": a.pointlens,
        "label": a.label,
        "pointlens_device": f"{dev.get('name', '?')} ({dev.get('driver_info', '?')}, Vulkan {dev.get('api_version', '?')})",
        "mitsuba": mi.__version__,
        "drjit": dr.__version__,
        "variant": a.variant,
        "llvm": os.environ.get("DRJIT_LIBLLVM_PATH"),
        "reps": a.reps,
        "repeat_limit_s": a.repeat_limit_s,
        "ref_spp": a.ref_spp,
        "pinhole_spp": a.pinhole_spp,
        "raster": a.raster or "pointlens's default",
        "lod_px": a.lod_px if a.lod_px is not None else "pointlens's default",
        "ssaa": a.ssaa or "pointlens's default",
        "coverage": a.coverage or "pointlens's default",
        "splat_shape": a.splat_shape,
        "command": ("scripts/bench-vs-mitsuba " + os.environ.get("BENCH_ARGS", "")).strip(),
        "load_average_1min": results.get("load_average_1min"),
    }
    if a.aperture_flags:
        env["aperture"] = " ".join(shlex.quote(w) for w in a.aperture_flags)
    return env


def write_csv(path, results):
    cols = ["scene", "renderer", "setting", "time_ms", "time_min_ms", "time_max_ms", "n", "first_ms",
            "psnr", "ssim", "gbuffer_psnr", "mitsuba_spp_same_psnr", "mitsuba_ms_same_psnr", "ratio", "same_psnr_note",
            "gpu_total_ms", "load_ms", "splat_sizes_ms", "upload_wall_ms", "process_ms"]
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for scene, info in results["scenes"].items():
            for r in info["rows"]:
                w.writerow([scene] + [fmt_csv(r.get(c)) for c in cols[1:]])


def fmt_csv(v):
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.4f}"
    return str(v)


def chart(path, results):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = results["scenes"]
    fig, axes = plt.subplots(1, len(scenes), figsize=(5.5 * len(scenes), 4.2), squeeze=False)
    for ax, (scene, info) in zip(axes[0], scenes.items()):
        mrows = [r for r in info["rows"] if r["renderer"] == "mitsuba"]
        prow = [r for r in info["rows"] if r["renderer"] == "pointlens"]
        ax.plot([r["time_ms"] / 1e3 for r in mrows], [r["psnr"] for r in mrows], "-o", color="tab:gray",
                ms=4, label="Mitsuba 3 (spp)")
        for r in mrows:
            ax.annotate(str(r["spp"]), (r["time_ms"] / 1e3, r["psnr"]), textcoords="offset points",
                        xytext=(3, -10), fontsize=7, color="tab:gray")
        for r in prow:
            ax.plot(r["time_ms"] / 1e3, r["psnr"], "s", color="tab:blue", ms=6)
            ax.annotate(r["setting"], (r["time_ms"] / 1e3, r["psnr"]), textcoords="offset points",
                        xytext=(5, 3), fontsize=8, color="tab:blue")
        ax.plot([], [], "s", color="tab:blue", label="pointlens (method)")
        ax.set_xscale("log")
        ax.set_xlabel("frame / render time, s (log)")
        ax.set_ylabel(f"PSNR dB vs Mitsuba {results['environment']['ref_spp']} spp")
        ax.set_title(f"{scene}: {info['points']:,} splats, {info['camera']['width']}×{info['camera']['height']}")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(loc="lower right", fontsize=8)
    env = results["environment"]
    fig.suptitle(f"{env['cpu']} ({env['cpu_count']} cores): pointlens on {env['pointlens_device'].split(' (')[0]}, "
                 f"Mitsuba {env['mitsuba']} {env['variant']}; {env['date']}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def ms(v):
    if v is None:
        return "—"
    return f"{v:,.0f}" if v >= 100 else f"{v:.1f}"


def markdown(results):
    env = results["environment"]
    md = results["max_depth_check"]
    lines = []
    lines.append(f"Measured {env['date']} with `{env['command'].strip()}`"
                 + (f" ({env['label']})" if env["label"] else "") + ".")
    lines.append(f"Machine: {env['cpu']}, {env['cpu_count']} cores. pointlens on {env['pointlens_device']}; "
                 f"Mitsuba {env['mitsuba']} (Dr.Jit {env['drjit']}), variant `{env['variant']}`"
                 + (f", LLVM `{Path(env['llvm']).name}`" if env["llvm"] and "llvm" in env["variant"] else "")
                 + ". 1-minute load average at the start of each round and at the end: "
                 + ", ".join(f"{v:.1f}" for v in env["load_average_1min"] or [])
                 + " (the benchmark itself keeps about 2 busy).")
    if env.get("aperture"):
        lines.append("")
        lines.append(f"Aperture: pointlens `{env['aperture']}`; Mitsuba's timed renders and reference through "
                     f"`aperture_thinlens` (scripts/mitsuba/aperture_sensor.py) built from the printed camera; "
                     f"the pinhole check and the max_depth check as without a shape.")
        for scene, skipped in results["aperture"]["skipped"].items():
            for name, why in skipped.items():
                lines.append(f"Skipped on {scene}: {name}, which refuses the shape (`{why}`).")
    lines.append("")
    for scene, info in results["scenes"].items():
        cam = info["camera"]
        pc = info["pinhole_check"]
        lines.append(f"**{scene}** (`{info['file']}`, {info['points']:,} splats, {cam['width']}×{cam['height']}, "
                     f"fovy {cam['fovy_deg']:.2f}°, R = {cam['aperture_radius']:g}, S = {cam['focus_distance']:.4f}; "
                     f"CoC of the points up to {info['coc_px_max']:.1f} px, background {info['coc_px_background']:.1f} px; "
                     f"median splat {info['splat_px_median']:.1f} px). Pinhole check, pointlens `pinhole` against "
                     f"Mitsuba at {env['pinhole_spp']} spp: {pc['psnr']:.2f} dB PSNR, SSIM {pc['ssim']:.4f} "
                     f"({pc['psnr_pointlens_ssaa8']:.2f} dB with `--ssaa 8`"
                     + (f"; {pc['psnr_without_tie_order']:.2f} dB without the tie order"
                        if "psnr_without_tie_order" in pc else "")
                     + (f"; {pc['psnr_without_1px_minimum']:.2f} dB without the 1 px minimum"
                        if "psnr_without_1px_minimum" in pc else "")
                     + f"; flipped in y {pc['psnr_flipped_y']:.1f} dB, in x {pc['psnr_flipped_x']:.1f} dB; "
                     f"centroid offset {pc['centroid_offset_px']['dx']:+.3f}, {pc['centroid_offset_px']['dy']:+.3f} px).")
        lines.append("")
        lines.append("| renderer | setting | time ms: median (min–max), n | first render (JIT) ms | PSNR dB | SSIM "
                     f"| G-buffer PSNR dB (pinhole, {env['ref_spp']} spp) | Mitsuba for the same PSNR "
                     "| Mitsuba time / pointlens time |")
        lines.append("|---|---|---:|---:|---:|---:|---:|---:|---:|")
        for r in info["rows"]:
            t = f"{ms(r['time_ms'])} ({ms(r['time_min_ms'])}–{ms(r['time_max_ms'])}), {r['n']}"
            if r["renderer"] == "pointlens":
                spp = r["mitsuba_spp_same_psnr"]
                note = " (extrap.)" if r["same_psnr_note"] else ""
                same = f"{spp:.1f} spp, {ms(r['mitsuba_ms_same_psnr'])} ms{note}" if spp else "—"
                ratio = f"{r['ratio']:.2f}{'*' if note else ''}" if r["ratio"] else "—"
                gb = f"{r['gbuffer_psnr']:.2f}" if r.get("gbuffer_psnr") is not None else "—"
                lines.append(f"| pointlens | {r['setting']} | {t} | — | {r['psnr']:.2f} | {r['ssim']:.4f} "
                             f"| {gb} | {same} | {ratio} |")
            else:
                lines.append(f"| Mitsuba | {r['setting']} | {t} | {ms(r['first_ms'])} | {r['psnr']:.2f} "
                             f"| {r['ssim']:.4f} | | | |")
        if any(r.get("same_psnr_note") for r in info["rows"]):
            lines.append("")
            lines.append("(extrap.), *: beyond the Mitsuba curve's sample counts, extrapolated along its "
                         "last segment.")
        p0 = next(r for r in info["rows"] if r["renderer"] == "pointlens")
        if "ratio_warm" in p0:
            lines.append("")
            lines.append("| pointlens | warm: steady frame ms | Mitsuba steady / it | cold: one-frame process ms "
                         "| Mitsuba first render / it |")
            lines.append("|---|---:|---:|---:|---:|")
            for r in info["rows"]:
                if r["renderer"] != "pointlens":
                    continue
                w = f"{r['ratio_warm']:.2f}" if r.get("ratio_warm") else "—"
                c = f"{r['ratio_cold']:.2f}" if r.get("ratio_cold") else "—"
                lines.append(f"| {r['setting']} | {ms(r['steady_ms'])} | {w} | {ms(r['process_ms'])} | {c} |")
        lines.append("")
        lines.append(f"Outside the times above: pointlens reads the file in {ms(p0['load_ms'])} ms and uploads "
                     f"in {ms(p0['upload_wall_ms'])} ms (splat sizes {ms(p0['splat_sizes_ms'])} ms), a whole "
                     f"`render` process of {p0['setting']} takes {ms(p0['process_ms'])} ms; Mitsuba builds the scene "
                     f"(squares, mesh, BVH) in {ms(info['mitsuba_build_ms'])} ms"
                     + (f" (plus {ms(info['squares']['tie_seconds'] * 1e3)} ms in Python ordering "
                        f"{info['squares']['tie_points_moved']:,} equal-depth squares as pointlens draws them)"
                        if info["squares"]["tie_points_moved"] else "")
                     + f"; the reference "
                     f"({env['ref_spp']} spp) rendered in {ms(info['reference_render_ms'])} ms.")
        lines.append("")
    lines.append(f"Mitsuba's `max_depth`, checked by rendering: the first scene's mean pixel value at max_depth "
                 f"0/1/2 is {md['scene_max_depth_0']:.4f}/{md['scene_max_depth_1']:.4f}/"
                 f"{md['scene_max_depth_2']:.4f}; in a probe scene (a gray wall lit by a lamp the camera "
                 f"sees from behind, and a small lamp facing the camera) the directly seen lamp reads "
                 f"{md['probe_max_depth_0_lamp_seen']:.3f}/{md['probe_max_depth_1_lamp_seen']:.3f}/"
                 f"{md['probe_max_depth_2_lamp_seen']:.3f} and the lit wall "
                 f"{md['probe_max_depth_0_wall']:.3f}/{md['probe_max_depth_1_wall']:.3f}/"
                 f"{md['probe_max_depth_2_wall']:.3f}: max_depth 1 is exactly the emitters seen directly.")
    return "\n".join(lines)


def main(argv):
    try:
        args = parse_args(argv)
        Bench(args).main()
    except Failure as e:
        print(f"bench-vs-mitsuba: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
