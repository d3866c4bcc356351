"""pointlens's splats as a Mitsuba 3 scene (DESIGN §2, §3).

Every splat becomes a square parallel to the camera's image plane, its sides
along the camera's right and up vectors, its side pointlens's world diameter
for that point, its front face toward the camera, emitting the point's linear
RGB radiance. All squares are one mesh; the colors are a per-face attribute
read by a `mesh_attribute` texture, so the scene builds in one go.

The camera is pointlens's (its `--print-camera` JSON): a `thinlens` sensor
(or `perspective` for aperture 0) with the vertical field of view, aperture
radius R, focus distance S and look_at(eye, target, up); an `hdrfilm` with a
box filter; the `path` integrator with `max_depth` 1 (directly seen emitters
only); black background.
"""

import struct
import time

import numpy as np

MAGIC = b"PLSPLAT1"


def read_splats(path):
    """The file of examples/export_splats.rs: (positions N×3, diameters N,
    linear colors N×3), float32."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != MAGIC:
        raise ValueError(f"{path}: not a splat file from examples/export_splats.rs")
    (count,) = struct.unpack_from("<Q", data, 8)
    rec = np.frombuffer(data, dtype="<f4", offset=16)
    if rec.size != count * 7:
        raise ValueError(f"{path}: {rec.size} floats for {count} splats (want 7 each)")
    rec = rec.reshape(count, 7)
    return rec[:, 0:3].copy(), rec[:, 3].copy(), rec[:, 4:7].copy()


def camera_basis(cam):
    """(eye, right, up', forward) of DESIGN §2: forward = normalize(target −
    eye); right = normalize(forward × up); up' = right × forward."""
    eye = np.asarray(cam["eye"], np.float64)
    forward = np.asarray(cam["target"], np.float64) - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(cam["up"], np.float64))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    return eye, right, up, forward


def f_px(cam):
    """Focal length in pixels: (H / 2) / tan(θ / 2)."""
    return (cam["height"] / 2.0) / np.tan(np.radians(cam["fovy_deg"]) / 2.0)


# Relative depth step between the levels of a tie (see tie_levels): about
# 16 float32 ulps, so that Mitsuba's float32 ray-triangle tests order them.
TIE_STEP = 2e-6


def tie_levels(cam, positions, sides):
    """pointlens resolves splats at exactly equal eye depth by the order of
    the vertices (strict LESS depth test: the earlier point wins); a ray
    tracer sees a coplanar overlap as a coin toss. The PCL scan has only 940
    distinct depths, so this decides most of its pixels. Per point, its
    level: 0 if no earlier point of the same float32 eye depth overlaps its
    square, else 1 + the highest level of those that do. Pushing each square
    back by `level` steps makes every earlier one of a tie nearer.

    Returns (levels, seconds)."""
    started = time.perf_counter()
    eye, right, up, forward = camera_basis(cam)
    e = positions.astype(np.float32) - eye.astype(np.float32)
    # The eye depth as the vertex shader computes it (float32 dot product).
    z = e @ forward.astype(np.float32)
    a = e @ right.astype(np.float32)
    b = e @ up.astype(np.float32)
    half = sides / 2.0
    level = np.zeros(len(z), np.int64)
    order = np.lexsort((np.arange(len(z)), z))
    zs = z[order]
    starts = np.flatnonzero(np.r_[True, zs[1:] != zs[:-1]])
    ends = np.r_[starts[1:], len(zs)]
    for s, t in zip(starts, ends):
        if t - s < 2:
            continue
        idx = order[s:t]  # ascending point index: drawing order
        ai, bi, hi = a[idx], b[idx], half[idx]
        cell = 2.0 * float(hi.max())
        ca = np.floor(ai / cell).astype(np.int64)
        cb = np.floor(bi / cell).astype(np.int64)
        grid = {}
        lv = np.zeros(len(idx), np.int64)
        for k in range(len(idx)):
            best = -1
            for dx in (-1, 0, 1):
                for dy in (-1, 0, 1):
                    for m in grid.get((ca[k] + dx, cb[k] + dy), ()):
                        r = hi[k] + hi[m]
                        if abs(ai[m] - ai[k]) < r and abs(bi[m] - bi[k]) < r and lv[m] > best:
                            best = lv[m]
            lv[k] = best + 1
            grid.setdefault((ca[k], cb[k]), []).append(k)
        level[idx] = lv
    return level, time.perf_counter() - started


# Sides of the polygon that stands for a disc splat (`--splat-shape disc`).
DISC_SIDES = 32


def square_mesh(cam, positions, diameters, min_px=1.0, ties=True, shape="square"):
    """Vertices (4N×3), faces (2N×3, uint32) of the camera-facing squares,
    and facts about them. With shape "disc", each splat is instead the disc
    inscribed in its square (pointlens `--splat-shape disc`): a regular
    polygon of DISC_SIDES sides, its radius scaled so that its area is the
    disc's (a triangle fan, DISC_SIDES faces a splat; the tie order is the
    squares', which hold the discs).

    pointlens draws a splat as a point sprite of f_px·d/z pixels clamped to
    at least `min_px` (glsl/splat_raster.vert: clamp(size, 1, max)); to draw
    the same splats, a square whose pinhole image would be smaller gets the
    side min_px·z/f_px. With min_px = 0 the squares keep their world size.
    With `ties`, equal-depth overlaps are ordered as pointlens orders them
    (tie_levels): each square moves back along its ray from the eye by
    TIE_STEP·level of its depth, its side growing alike, so its image does
    not change. The step shrinks where the next depth behind is closer than
    the largest level's offset (then the order may be unreliable: counted).
    """
    eye, right, up, forward = camera_basis(cam)
    p = positions.astype(np.float64)
    z = (p - eye) @ forward
    d = diameters.astype(np.float64)
    facts = {"enlarged_to_min_px": 0, "tie_max_level": 0, "tie_points_moved": 0, "tie_seconds": 0.0,
             "tie_unreliable_groups": 0}
    if min_px > 0:
        floor = min_px * np.maximum(z, 0.0) / f_px(cam)
        facts["enlarged_to_min_px"] = int(np.count_nonzero(d < floor))
        d = np.maximum(d, floor)
    if ties:
        level, seconds = tie_levels(cam, positions, d)
        facts.update(tie_max_level=int(level.max(initial=0)), tie_points_moved=int(np.count_nonzero(level)),
                     tie_seconds=seconds)
        if level.any():
            # Per distinct depth: the step, at most half the way to the next
            # depth behind it over the group's largest level.
            uz, inverse = np.unique(z, return_inverse=True)
            gap = np.r_[np.diff(uz), np.inf] / uz
            top = np.zeros(len(uz), np.int64)
            np.maximum.at(top, inverse, level)
            step = np.minimum(TIE_STEP, 0.5 * gap / np.maximum(top, 1))
            facts["tie_unreliable_groups"] = int(np.count_nonzero((top > 0) & (step < TIE_STEP / 4)))
            scale = 1.0 + step[inverse] * level
            p = eye + (p - eye) * scale[:, None]
            d = d * scale
    h = (d / 2.0)[:, None]
    if shape == "disc":
        n = DISC_SIDES
        # A regular n-gon of circumradius ρ has area (n/2)·sin(2π/n)·ρ².
        rho = h * np.sqrt(np.pi / (0.5 * n * np.sin(2.0 * np.pi / n)))
        angles = 2.0 * np.pi * np.arange(n) / n
        # Counter-clockwise seen from the camera (right, then up'), as below.
        rim = (np.cos(angles)[None, :, None] * right[None, None, :]
               + np.sin(angles)[None, :, None] * up[None, None, :])
        ring = p[:, None, :] + rho[:, :, None] * rim
        vertices = np.concatenate([p[:, None, :], ring], axis=1).reshape(-1, 3).astype(np.float32)
        base = (np.arange(len(p), dtype=np.uint32) * (n + 1))[:, None, None]
        k = np.arange(n, dtype=np.uint32)
        fan = np.stack([np.zeros(n, np.uint32), 1 + k, 1 + (k + 1) % n], axis=1)[None, :, :]
        faces = (base + fan).reshape(-1, 3)
        return vertices, faces, facts
    # Counter-clockwise seen from the camera: the face normal
    # (v1 − v0) × (v2 − v0) ∝ right × up' = −forward points at the camera,
    # the side an area emitter emits from.
    corners = np.stack(
        [p - h * right - h * up, p + h * right - h * up, p + h * right + h * up, p - h * right + h * up],
        axis=1,
    )
    vertices = corners.reshape(-1, 3).astype(np.float32)
    base = (np.arange(len(p), dtype=np.uint32) * 4)[:, None]
    faces = (base + np.array([0, 1, 2, 0, 2, 3], np.uint32)[None, :]).reshape(-1, 3)
    return vertices, faces, facts


def sensor_dict(mi, cam, sample_count=1):
    """The Mitsuba sensor of a pointlens camera."""
    eye = [float(v) for v in cam["eye"]]
    target = [float(v) for v in cam["target"]]
    up = [float(v) for v in cam["up"]]
    sensor = {
        "fov": float(cam["fovy_deg"]),
        "fov_axis": "y",
        "to_world": mi.ScalarTransform4f().look_at(origin=eye, target=target, up=up),
        "film": {
            "type": "hdrfilm",
            "width": int(cam["width"]),
            "height": int(cam["height"]),
            "rfilter": {"type": "box"},
            "pixel_format": "rgb",
            "component_format": "float32",
        },
        "sampler": {"type": "independent", "sample_count": sample_count},
    }
    # The splats' depths are far beyond the default near clip (0.01) for the
    # bundled scenes; keep it, and a far clip beyond everything.
    sensor["far_clip"] = 1e6
    if cam["aperture_radius"] > 0:
        sensor["type"] = "thinlens"
        sensor["aperture_radius"] = float(cam["aperture_radius"])
        sensor["focus_distance"] = float(cam["focus_distance"])
    else:
        sensor["type"] = "perspective"
    return sensor


def build_scene(mi, cam, positions, diameters, colors, max_depth=1, min_px=1.0, ties=True, shape="square",
                sensor=None):
    """The Mitsuba scene and facts about its build (square_mesh's, and
    build_s: the seconds of all of it but the tie ordering). `sensor`: a
    Mitsuba sensor dict in place of sensor_dict's `thinlens` (e.g.
    aperture_sensor.sensor_from_camera's)."""
    started = time.perf_counter()
    vertices, faces, facts = square_mesh(cam, positions, diameters, min_px, ties, shape)
    props = mi.Properties()
    props["emitter"] = mi.load_dict(
        {"type": "area", "radiance": {"type": "mesh_attribute", "name": "face_color"}}
    )
    # Black: no light leaves a square but its own emission, whatever max_depth.
    props["bsdf"] = mi.load_dict({"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}})
    mesh = mi.Mesh("splats", len(vertices), len(faces), props=props)
    params = mi.traverse(mesh)
    params["vertex_positions"] = vertices.ravel()
    params["faces"] = faces.ravel()
    # Every triangle of a splat carries its color.
    per_splat = len(faces) // max(len(colors), 1)
    mesh.add_attribute("face_color", 3, np.repeat(colors.astype(np.float32), per_splat, axis=0).ravel())
    params.update()
    scene = mi.load_dict(
        {
            "type": "scene",
            "integrator": {"type": "path", "max_depth": max_depth},
            "sensor": sensor if sensor is not None else sensor_dict(mi, cam),
            "splats": mesh,
        }
    )
    facts["build_s"] = time.perf_counter() - started - facts["tie_seconds"]
    return scene, facts


def render(mi, dr, scene, spp, seed):
    """One render, synchronised: (image H×W×3 float32 numpy, seconds)."""
    started = time.perf_counter()
    img = mi.render(scene, spp=spp, seed=seed)
    dr.eval(img)
    dr.sync_thread()
    seconds = time.perf_counter() - started
    return np.array(img, dtype=np.float32), seconds


def write_exr(mi, path, image):
    """A linear float32 RGB EXR."""
    bmp = mi.Bitmap(np.ascontiguousarray(image, dtype=np.float32), pixel_format=mi.Bitmap.PixelFormat.RGB)
    bmp.write(str(path))
