"""CoC-band pyramid scatter-as-gather.
Sources P: premultiplied (w c, w), w = 1/N(r_P) (N = pixel centres in P's disk), r = CoC/2.
Level 0 (full res): sources with r < B, exact discrete rule: tap at integer offset d accepted if r_P >= |d|.
Level L>=1 (texel t=2^L): sources with B*2^(L-1) <= r < B*2^L, block-summed into texels (sum of w c, sum of w, w-weighted mean r);
  gather over integer texel offsets d with |d| < B+0.7071, weight ov_d(rho), rho = r/t, ov_d = area fraction of the unit cell at d
  covered by a disk of radius rho whose centre is uniform in the source cell ... (here: exact table by supersampling).
  Result bilinearly upsampled to full res; all levels summed.
Output: rgb (variant plain) or rgb/max(1, sum w) (variant norm)."""
import sys, time, numpy as np
from common import *

def ov_table(B, nr=256, ss=24):
    Dm = B + 0.7072
    R = int(np.ceil(Dm))
    offs = [(dy, dx) for dy in range(-R, R + 1) for dx in range(-R, R + 1) if dx * dx + dy * dy < Dm * Dm]
    u = (np.arange(ss) + 0.5) / ss - 0.5
    uy, ux = np.meshgrid(u, u, indexing='ij'); uy = uy.ravel(); ux = ux.ravel()
    rhos = np.linspace(0, B, nr + 1)
    tab = np.zeros((len(offs), nr + 1), np.float32)
    for k, (dy, dx) in enumerate(offs):
        dist = np.sqrt((dy - uy) ** 2 + (dx - ux) ** 2)   # target at cell centre d, source uniform in cell at 0
        tab[k] = (dist[None, :] <= rhos[:, None]).mean(1)
    # drop taps that never get weight
    keep = tab.max(1) > 0
    return [o for o, kk in zip(offs, keep) if kk], tab[keep], rhos

def shift(a, dy, dx, pad):
    # a padded by `pad`; returns view of a at (y+dy, x+dx) for the unpadded domain
    h = a.shape[0] - 2 * pad; w = a.shape[1] - 2 * pad
    return a[pad + dy:pad + dy + h, pad + dx:pad + dx + w]

def upsample(a, t, H, W):
    """bilinear upsample level array a (h,w,C) with texel size t to (H,W,C); texel centres at (i+0.5)t-0.5."""
    def axis_idx(n_out, n_in):
        x = (np.arange(n_out) + 0.5) / t - 0.5
        i0 = np.floor(x).astype(int); f = (x - i0).astype(np.float32)
        i1 = np.clip(i0 + 1, 0, n_in - 1); i0 = np.clip(i0, 0, n_in - 1)
        return i0, i1, f
    y0, y1, fy = axis_idx(H, a.shape[0]); x0, x1, fx = axis_idx(W, a.shape[1])
    r0 = a[y0]; r1 = a[y1]
    rows = r0 + (r1 - r0) * fy[:, None, None]
    c0 = rows[:, x0]; c1 = rows[:, x1]
    return c0 + (c1 - c0) * fx[None, :, None]

def run(S, B=3, Lmax=6, stats=None):
    rgb, z, coc, cam = load(S)
    bg = ~np.isfinite(z)
    r = (coc / 2).astype(np.float32)
    w = 1.0 / ncount(r)
    H0, W0 = z.shape
    M = 2 ** Lmax
    Hp = -(-H0 // M) * M; Wp = -(-W0 // M) * M
    def padto(x):
        pw = [(0, Hp - H0), (0, Wp - W0)] + [(0, 0)] * (x.ndim - 2)
        return np.pad(x, pw)
    src = np.concatenate([rgb * w[..., None], w[..., None]], -1).astype(np.float32)   # premultiplied (wc, w); bg: c=0
    srcE = padto(np.concatenate([rgb, np.ones_like(r)[..., None]], -1).astype(np.float32))
    src = padto(src); rp = padto(r); valid = padto(np.ones_like(r, bool))
    out = np.zeros((Hp, Wp, 4), np.float32)
    ntaps = {}
    # level 0: exact discrete
    m0 = (rp < B) & valid
    s0 = src * m0[..., None]; r0 = np.where(m0, rp, -1)
    R = int(np.floor(B))
    pad = R + 1
    s0p = np.pad(s0, [(pad, pad), (pad, pad), (0, 0)]); r0p = np.pad(r0, pad, constant_values=-1)
    offs0 = [(dy, dx) for dy in range(-R, R + 1) for dx in range(-R, R + 1) if dx * dx + dy * dy < B * B]
    for dy, dx in offs0:
        d = np.float32(np.hypot(dy, dx))
        acc = shift(r0p, dy, dx, pad) >= d
        out += shift(s0p, dy, dx, pad) * acc[..., None]
    ntaps[0] = len(offs0)
    offs, tab, rhos = ov_table(B)
    tab = tab / np.maximum(tab.sum(0, keepdims=True), 1e-12)
    nr = len(rhos) - 1
    for L in range(1, Lmax + 1):
        t = 2 ** L
        lo, hi = B * 2 ** (L - 1), B * 2 ** L
        m = (rp >= lo) & (rp < hi) & valid
        if L == Lmax: m = (rp >= lo) & valid
        if not m.any(): continue
        # energy-conserving: texel = mean over its t*t pixels of (c, 1) of band sources; spread normalised to sum 1
        sL = (srcE * m[..., None]).reshape(Hp // t, t, Wp // t, t, 4).mean((1, 3))
        rw = (rp * rp * m).reshape(Hp // t, t, Wp // t, t).mean((1, 3))
        rho = np.where(sL[..., 3] > 0, np.sqrt(rw / np.maximum(sL[..., 3], 1e-30)) / t, 0)
        ridx = np.clip(np.rint(rho / B * nr), 0, nr).astype(np.int32)
        pad = int(np.ceil(B + 0.71)) + 1
        sLp = np.pad(sL, [(pad, pad), (pad, pad), (0, 0)]); rip = np.pad(ridx, pad)
        oL = np.zeros_like(sL)
        for k, (dy, dx) in enumerate(offs):
            wk = tab[k][shift(rip, dy, dx, pad)]
            oL += shift(sLp, dy, dx, pad) * wk[..., None]
        ntaps[L] = len(offs)
        out += upsample(oL, t, Hp, Wp)
    out = out[:H0, :W0]
    o = crop(out)
    taps_per_px = ntaps[0] + sum(n / 4 ** L for L, n in ntaps.items() if L > 0)
    return o, ntaps, taps_per_px

if __name__ == '__main__':
    B = float(sys.argv[1]) if len(sys.argv) > 1 else 3
    for S in (sys.argv[2].split(',') if len(sys.argv) > 2 else SCENES):
        t0 = time.time()
        o, ntaps, tpp = run(S, B)
        for name, img in [('plain', o[..., :3]), ('norm', o[..., :3] / np.maximum(o[..., 3:], 1))]:
            p = f'{WORK}/{S}_bandE{B:g}_{name}.exr'; write(p, img)
            print(S, f'B={B}', name, 'taps', ntaps, f'taps/px {tpp:.1f}', 'psnr', psnr(p, S), f'{time.time()-t0:.1f}s', flush=True)
