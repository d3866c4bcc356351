"""Tapped Jimenez-style DOF ("J2"): near field by CoC-band pyramid scatter (alpha), far field by a per-pixel gather
of radius r_Q (receiver's own CoC radius) on a ring pattern over a far-field mip, fg/bg split per tap vs the centre depth.
usage: jtap.py K B [scenes]   K: rings (taps 1+8+..+8K), B: band factor of the near-field pyramid (0: no near field pass)"""
import sys, time, numpy as np
from common import *
import bandscatter2 as bs
import os
BGMODE = int(os.environ.get('BGMODE', '1'))
AA0 = int(os.environ.get('AA0', '1'))
CENTROID = int(os.environ.get('CENTROID', '0'))

def mips(fields, Lmax):
    """fields: (H,W,C) premultiplied sums; returns list of means per level (level 0 = input)."""
    out = [fields]
    a = fields
    for L in range(1, Lmax + 1):
        h, w = a.shape[0] // 2, a.shape[1] // 2
        a = a[:2 * h, :2 * w].reshape(h, 2, w, 2, -1).mean((1, 3))
        out.append(a)
    return out

def bilin(a, y, x):
    """bilinear fetch of a (h,w,C) at continuous texel coords (y,x) (texel centres at integers), clamped."""
    h, w = a.shape[:2]
    y0 = np.floor(y).astype(np.int32); x0 = np.floor(x).astype(np.int32)
    fy = (y - y0).astype(np.float32)[:, None]; fx = (x - x0).astype(np.float32)[:, None]
    y0c = np.clip(y0, 0, h - 1); y1c = np.clip(y0 + 1, 0, h - 1); x0c = np.clip(x0, 0, w - 1); x1c = np.clip(x0 + 1, 0, w - 1)
    a00 = a[y0c, x0c]; a01 = a[y0c, x1c]; a10 = a[y1c, x0c]; a11 = a[y1c, x1c]
    top = a00 + (a01 - a00) * fx; bot = a10 + (a11 - a10) * fx
    return top + (bot - top) * fy

def ring_pattern(K):
    pts = [(0.0, 0.0, 0.0)]
    for k in range(1, K + 1):
        n = 8 * k
        for j in range(n):
            th = 2 * np.pi * (j + 0.5 * (k % 2)) / n
            pts.append((k * np.sin(th), k * np.cos(th), float(k)))
    return np.array(pts, np.float32)   # (dy, dx, |d|) in units of s

_OV0 = {}
def ov0_table(Rmax, nr=512, ss=32):
    """ov0[d](rho): area of disk(rho, centred at the source pixel centre) inside the receiver pixel square at offset d,
    normalised over d to sum 1 (energy conserving; rho->0 gives the identity)."""
    key = Rmax
    if key in _OV0: return _OV0[key]
    R = int(np.ceil(Rmax + 0.71))
    offs = [(dy, dx) for dy in range(-R, R + 1) for dx in range(-R, R + 1) if dy * dy + dx * dx < (Rmax + 0.71) ** 2]
    u = (np.arange(ss) + 0.5) / ss - 0.5
    uy, ux = np.meshgrid(u, u, indexing='ij'); uy = uy.ravel(); ux = ux.ravel()
    rhos = np.linspace(0, Rmax, nr + 1); rhos[0] = 1e-3
    tab = np.zeros((len(offs), nr + 1), np.float32)
    for k, (dy, dx) in enumerate(offs):
        dist = np.sqrt((dy + uy) ** 2 + (dx + ux) ** 2)
        tab[k] = (dist[None, :] <= rhos[:, None]).mean(1)
    tab[offs.index((0, 0)), tab.sum(0) == 0] = 1
    tab /= tab.sum(0, keepdims=True)
    _OV0[key] = (offs, tab, nr / Rmax)
    return _OV0[key]

def near_band(S, B, rgb, z, r, f):
    """energy-form band scatter of near-field sources (z < f) -> (premult rgb, alpha) cropped."""
    near = z < f
    rgbn = np.where(near[..., None], rgb, 0); rn = np.where(near, r, 0)
    return band_energy(rgbn, near.astype(np.float32), rn, B)

def band_energy(rgb, cnt, r, B, Lmax=6):
    B0 = float(os.environ.get('B0', B))
    H0, W0 = r.shape; M = 2 ** Lmax
    Hp = -(-H0 // M) * M; Wp = -(-W0 // M) * M
    def padto(x): return np.pad(x, [(0, Hp - H0), (0, Wp - W0)] + [(0, 0)] * (x.ndim - 2))
    w = 1.0 / ncount(r)
    srcE = padto(np.concatenate([rgb, cnt[..., None]], -1).astype(np.float32))
    src0 = padto(np.concatenate([rgb * w[..., None], (cnt * w)[..., None]], -1).astype(np.float32))
    rp = padto(r); cp = padto(cnt) > 0
    out = np.zeros((Hp, Wp, 4), np.float32)
    m0 = (rp < B0) & cp
    R = int(np.floor(B0)); pad = R + 1
    s0p = np.pad(src0 * m0[..., None], [(pad, pad), (pad, pad), (0, 0)]); r0p = np.pad(np.where(m0, rp, -1), pad, constant_values=-1)
    if AA0:
        offs0, tab0, sc0 = ov0_table(B0)
        pad = int(np.ceil(B0 + 0.71)) + 1
        s0p = np.pad(srcE * m0[..., None], [(pad, pad), (pad, pad), (0, 0)]); r0p = np.pad(np.where(m0, rp, 0), pad)
        ri = np.clip(np.rint(r0p * sc0), 0, tab0.shape[1] - 1).astype(np.int32)
        for k, (dy, dx) in enumerate(offs0):
            out += bs.shift(s0p, dy, dx, pad) * tab0[k][bs.shift(ri, dy, dx, pad)][..., None]
    else:
      for dy in range(-R, R + 1):
        for dx in range(-R, R + 1):
            if dx * dx + dy * dy < B * B:
                out += bs.shift(s0p, dy, dx, pad) * (bs.shift(r0p, dy, dx, pad) >= np.hypot(dy, dx))[..., None]
    offs, tab, rhos = bs.ov_table(B); tab = tab / np.maximum(tab.sum(0, keepdims=True), 1e-12); nr = len(rhos) - 1
    for L in range(1, Lmax + 1):
        t = 2 ** L; lo, hi = B * 2 ** (L - 1), B * 2 ** L
        if L == 1: lo = B0
        m = (rp >= lo) & ((rp < hi) if L < Lmax else True) & cp
        if not m.any(): continue
        sL = (srcE * m[..., None]).reshape(Hp // t, t, Wp // t, t, 4).mean((1, 3))
        rw = (rp * rp * m).reshape(Hp // t, t, Wp // t, t).mean((1, 3))
        rho = np.where(sL[..., 3] > 0, np.sqrt(rw / np.maximum(sL[..., 3], 1e-30)) / t, 0)
        pad = int(np.ceil(B + 0.71)) + 1
        oL = np.zeros_like(sL)
        if CENTROID:
            # count-weighted centroid of the band's sources inside the texel, in texel units relative to the texel centre
            sub = ((np.arange(t) + 0.5) / t - 0.5).astype(np.float32)
            mm = m.reshape(Hp // t, t, Wp // t, t).astype(np.float32)
            cn = np.maximum(mm.sum((1, 3)), 1e-9)
            cy = (mm * sub[None, :, None, None]).sum((1, 3)) / cn; cx = (mm * sub[None, None, None, :]).sum((1, 3)) / cn
            Rg = int(np.ceil(B + 1.5))
            offsC = [(dy, dx) for dy in range(-Rg, Rg + 1) for dx in range(-Rg, Rg + 1)]
            # weight of source texel (at +d from receiver, centroid c) for the receiver: clamp(rho - |d + c| + 0.5)
            Ssum = np.zeros_like(rho)
            for dy, dx in offsC:
                Ssum += np.clip(rho - np.hypot(dy + cy, dx + cx) + 0.5, 0, 1)
            pad = Rg + 1
            sLn = sL / np.maximum(Ssum, 1e-9)[..., None]
            sLp = np.pad(sLn, [(pad, pad), (pad, pad), (0, 0)]); rp_ = np.pad(rho, pad); cyp = np.pad(cy, pad); cxp = np.pad(cx, pad)
            for dy, dx in offsC:
                wk = np.clip(bs.shift(rp_, dy, dx, pad) - np.hypot(dy + bs.shift(cyp, dy, dx, pad), dx + bs.shift(cxp, dy, dx, pad)) + 0.5, 0, 1)
                oL += bs.shift(sLp, dy, dx, pad) * wk[..., None]
        else:
            ridx = np.clip(np.rint(rho / B * nr), 0, nr).astype(np.int32)
            sLp = np.pad(sL, [(pad, pad), (pad, pad), (0, 0)]); rip = np.pad(ridx, pad)
            for k, (dy, dx) in enumerate(offs):
                oL += bs.shift(sLp, dy, dx, pad) * tab[k][bs.shift(rip, dy, dx, pad)][..., None]
        out += bs.upsample(oL, t, Hp, Wp)
    return crop(out[:H0, :W0])

def far_gather(rgb, z, r, f, K, soft=True, eps=0.0):
    """per-pixel gather radius r_Q over far-field sources (z >= f). Returns fg premult (rgb, alpha) and bg (rgb, w)."""
    H0, W0 = z.shape
    far = (z >= f).astype(np.float32)
    iz = np.where(np.isfinite(z), 1.0 / z, 0.0).astype(np.float32)      # inverse depth, 0 at infinity
    fields = np.concatenate([rgb * far[..., None], far[..., None], (r * far)[..., None], (iz * far)[..., None]], -1).astype(np.float32)
    Lmax = 6
    mp = mips(fields, Lmax)
    zc = crop(z); rc = crop(r); izc = crop(iz)
    h, w = zc.shape
    yy, xx = np.mgrid[0:h, 0:w]; yy = (yy + G).ravel().astype(np.float32); xx = (xx + G).ravel().astype(np.float32)
    izq = izc.ravel(); rq = rc.ravel()
    fgC = np.zeros((h * w, 4), np.float32); bgC = np.zeros((h * w, 4), np.float32)
    pat = ring_pattern(K)
    small = rq < K + 0.5
    # small radii: exact integer offsets |d| <= r_Q at level 0
    Rs = int(np.floor(K + 0.5))
    lvl = np.where(small, -1, np.clip(np.rint(np.log2(np.maximum(rq / (K + 0.5), 1))), 0, Lmax)).astype(int)
    groups = [(-1, np.nonzero(small)[0])] + [(L, np.nonzero(lvl == L)[0]) for L in range(0, Lmax + 1)]
    for L, idx in groups:
        if len(idx) == 0: continue
        y = yy[idx]; x = xx[idx]; izQ = izq[idx]; rQ = rq[idx]
        if L == -1:
            taps = [(dy, dx, np.hypot(dy, dx)) for dy in range(-Rs, Rs + 1) for dx in range(-Rs, Rs + 1) if dy * dy + dx * dx <= (K + 0.5) ** 2]
            if AA0:
                offs0, tab0, sc0 = ov0_table(K + 0.5)
                taps = [(dy, dx, np.hypot(dy, dx)) for dy, dx in offs0]
            s = np.ones_like(rQ); A = np.ones_like(rQ); level = 0
        else:
            s = rQ / (K + 0.5); A = np.pi * rQ ** 2 / len(pat); level = L
            taps = [tuple(p) for p in pat]
        t = 2.0 ** level
        for dy, dx, dk in taps:
            if L == -1:
                if dk > 0:
                    pass
                inside = (dk <= rQ).astype(np.float32)
                py = y + dy; px = x + dx; dist = np.full_like(rQ, dk)
            else:
                inside = 1.0
                py = y + dy * s; px = x + dx * s; dist = dk * s
            v = bilin(mp[level], (py + 0.5) / t - 0.5, (px + 0.5) / t - 0.5)
            n = v[:, 3]
            ok = n > 1e-6
            cbar = v[:, :3] / np.maximum(n, 1e-6)[:, None]
            rbar = v[:, 4] / np.maximum(n, 1e-6); izbar = v[:, 5] / np.maximum(n, 1e-6)
            fg = izbar > izQ * (1 + eps)
            if soft and L != -1:
                cov = np.clip((rbar - dist) / s + 0.5, 0, 1)
                covb = np.clip((np.minimum(rbar, rQ) - dist) / s + 0.5, 0, 1)
            else:
                cov = (rbar >= dist).astype(np.float32); covb = (np.minimum(rbar, rQ) >= dist).astype(np.float32)
            if L == -1 and AA0:
                k0 = offs0.index((int(dy), int(dx)))
                # source at Q+d spreads into receiver pixel Q (offset -d from the source): table is symmetric
                inside = 1.0
                cov = tab0[k0][np.clip(np.rint(rbar * sc0), 0, tab0.shape[1] - 1).astype(np.int32)] * ncount(rbar)
                rb = np.minimum(rbar, rQ)
                covb = tab0[k0][np.clip(np.rint(rb * sc0), 0, tab0.shape[1] - 1).astype(np.int32)] * ncount(rb)
                # rQ < K+0.5 so the disk of min(rbar,rQ) fits the table; the disk of rbar may not (rare): clipped
            if L != -1 and dk == 0:
                # centre tap stands for the disk of radius s/2 around Q: only sources within r of Q reach Q
                cov = np.pi * np.minimum(rbar, s / 2) ** 2 / A
                covb = np.pi * np.minimum(np.minimum(rbar, rQ), s / 2) ** 2 / A
            wf = np.where(fg & ok, A * n * cov / ncount(rbar), 0) * inside
            wb = np.where(~fg & ok, A * n * covb / ncount(np.minimum(rbar, rQ)), 0) * inside
            fgC[idx, :3] += wf[:, None] * cbar; fgC[idx, 3] += wf
            bgC[idx, :3] += wb[:, None] * cbar; bgC[idx, 3] += wb
    return fgC.reshape(h, w, 4), bgC.reshape(h, w, 4)

def run(S, K, B, soft=True, eps=0.0, near_mode='band'):
    global EPS
    rgb, z, coc, cam = load(S)
    r = (coc / 2).astype(np.float32); f = cam['focus_distance']
    t0 = time.time()
    fgC, bgC = far_gather(rgb, z, r, f, K, soft, eps)
    if B > 0 and (z < f).any():
        nb = near_band(S, B, rgb, z, r, f)
        fgC = fgC + nb
    zc = crop(z)
    if BGMODE and (~np.isfinite(zc)).any():
        # receivers at infinity: fg = band scatter of all finite sources, bg = the background itself (black)
        fin = np.isfinite(z)
        allb = band_energy(np.where(fin[..., None], rgb, 0), fin.astype(np.float32), np.where(fin, r, 0), B if B > 0 else 3)
        inf = ~np.isfinite(zc)
        fgC = np.where(inf[..., None], allb, fgC)
        bgC = np.where(inf[..., None], np.array([0, 0, 0, 1], np.float32), bgC)
    a = np.clip(fgC[..., 3:], 0, 1)
    a = np.where(bgC[..., 3:] > 1e-9, a, 1.0)
    out = fgC[..., :3] / np.maximum(fgC[..., 3:], 1e-12) * a + bgC[..., :3] / np.maximum(bgC[..., 3:], 1e-12) * (1 - a)
    return out, time.time() - t0

if __name__ == '__main__':
    K = int(sys.argv[1]); B = float(sys.argv[2]); eps = float(sys.argv[4]) if len(sys.argv) > 4 else 0.0
    for S in (sys.argv[3].split(',') if len(sys.argv) > 3 and sys.argv[3] != 'all' else SCENES):
        out, dt = run(S, K, B, eps=eps)
        p = f'{WORK}/{S}_jtap_K{K}_B{B:g}_e{eps:g}_c{CENTROID}_b0{os.environ.get("B0", B)}.exr'; write(p, out)
        print(S, f'K={K} B={B}', 'psnr', psnr(p, S), f'{dt:.1f}s', flush=True)
