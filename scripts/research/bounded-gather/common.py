import numpy as np, json, subprocess, os
import mitsuba as mi
mi.set_variant('scalar_rgb')
G = 96
SCENES = ['bunny', 'mug', 'autzen']
# WORK: images and scratch; POINTLENS: the binary; BENCH: scripts/bench-vs-mitsuba's
# work folder (its cameras and Mitsuba references at 1920x1080).
WORK = os.environ.get('WORK', '/tmp/bounded-gather')
POINTLENS = os.environ.get('POINTLENS', 'pointlens')
BENCH = os.environ.get('BENCH', os.path.expanduser('~/.cache/pointlens/bench-mitsuba'))
os.makedirs(WORK, exist_ok=True)

def load(S):
    """Extended G-buffer (guard G on each side). Returns rgb (H,W,3), z (inf on bg), coc diameter (px)."""
    a = np.array(mi.Bitmap(f'{WORK}/{S}_ext.exr'))
    rgb = np.ascontiguousarray(a[..., :3]); z = np.ascontiguousarray(a[..., 3]); coc = np.ascontiguousarray(a[..., 5])
    cam = json.load(open(f'{BENCH}/{S}/camera.json'))
    return rgb, z, coc, cam

def crop(x):
    return x[G:-G, G:-G]

def write(path, rgb):
    mi.Bitmap(np.ascontiguousarray(rgb.astype(np.float32)), channel_names=['R', 'G', 'B']).write(path)

def psnr(path, S):
    out = subprocess.run([POINTLENS, 'compare', path, f'{BENCH}/{S}/mitsuba_ref_1024spp.exr'],
                         capture_output=True, text=True).stdout
    d = dict(l.split(': ') for l in out.strip().splitlines())
    return float(d['psnr'])

# N(r): number of integer pixel offsets with dx^2+dy^2 <= r^2
_R = 200
_yy, _xx = np.mgrid[-_R:_R + 1, -_R:_R + 1]
_D2 = np.sort((_xx * _xx + _yy * _yy).ravel()).astype(np.float64)
def ncount(r):
    r = np.asarray(r, np.float64)
    return np.maximum(np.searchsorted(_D2, r * r, side='right'), 1).astype(np.float32)

def srgb(x):
    x = np.clip(x, 0, 1)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)

def load_ref(S):
    return np.array(mi.Bitmap(f'{BENCH}/{S}/mitsuba_ref_1024spp.exr'))[..., :3]

def dense_inputs(S):
    """What the dense (every offset) rules share: the G-buffer, background mask, CoC radius r,
    weight 1/N(r), and depth with the background at a finite far value."""
    rgb, z, coc, cam = load(S)
    bg = ~np.isfinite(z)
    r = coc / 2
    zf = np.where(bg, np.float32(3e38), z).astype(np.float32)
    return rgb, z, coc, cam, bg, r, 1.0 / ncount(r), zf
