"""Dense (all offsets) evaluation of several per-pixel gather rules; Zhao's fast exactly as defined.
P = source pixel at q+d; accept for Zhao if |d| <= c_P/2 and z_P <= z_Q; weight 1/N(c_P/2)."""
import sys, time, numpy as np
from common import *
S = sys.argv[1]
rgb, z, coc, cam, bg, r, wN, zf = dense_inputs(S)
H, W = z.shape
rfg = r[~bg].max()
R = int(np.ceil(rfg))
h, w = H - 2 * G, W - 2 * G
zQ = crop(zf); rQ = crop(r); bgQ = crop(bg)
# accumulators
zh_c = np.zeros((h, w, 3), np.float32); zh_w = np.zeros((h, w), np.float32)      # Zhao (fg sources only; bg sources added below)
sc_c = np.zeros((h, w, 3), np.float32); sc_w = np.zeros((h, w), np.float32)      # plain scatter-as-gather, no depth test
# "occluded scatter": sources in front of or at Q (z_P<=z_Q) scatter; sources behind Q limited to Q's own CoC (gather with own CoC)
jf_c = np.zeros((h, w, 3), np.float32); jf_w = np.zeros((h, w), np.float32)   # fg field: z_P < z_Q: scatter weight 1/N_P
jb_c = np.zeros((h, w, 3), np.float32); jb_w = np.zeros((h, w), np.float32)   # bg field: z_P >= z_Q, [min(r_P,r_Q)>=d], weight 1
t0 = time.time()
offs = [(dy, dx) for dy in range(-R, R + 1) for dx in range(-R, R + 1) if dx * dx + dy * dy <= R * R]
for dy, dx in offs:
    d = np.float32(np.sqrt(dx * dx + dy * dy))
    sl = (slice(G + dy, G + dy + h), slice(G + dx, G + dx + w))
    rP = r[sl]; zP = zf[sl]; cP = rgb[sl]; wP = wN[sl]; bP = bg[sl]
    cover = rP >= d
    # Zhao: fg sources only here
    m = cover & (zP <= zQ) & ~bP
    ww = np.where(m, wP, 0); zh_w += ww; zh_c += ww[..., None] * cP
    # plain scatter
    ww = np.where(cover, wP, 0); sc_w += ww; sc_c += ww[..., None] * cP
    # fg field
    front = zP < zQ
    ww = np.where(cover & front, wP, 0); jf_w += ww; jf_c += ww[..., None] * cP
    ww = ((np.minimum(rP, rQ) >= d) & ~front).astype(np.float32); jb_w += ww; jb_c += ww[..., None] * cP
print('loop', len(offs), 'offsets', time.time() - t0, 's', flush=True)
# Zhao: background sources (black, CoC r_bg) for background Q: count bg pixels within r_bg (FFT disk convolution)
rbg = float(r[bg].max()) if bg.any() else 0
Rb = int(np.floor(rbg))
yy, xx = np.mgrid[-Rb:Rb + 1, -Rb:Rb + 1]
K = (xx * xx + yy * yy <= rbg * rbg).astype(np.float64)
Nbg = K.sum()
# pad the bg mask so that the disk can reach beyond the guard: outside the extended frame is unknown; assume bg there
pad = Rb + 1
M = np.pad(bg.astype(np.float64), pad, constant_values=1.0)
from numpy.fft import rfft2, irfft2
sh = (M.shape[0] + K.shape[0], M.shape[1] + K.shape[1])
conv = irfft2(rfft2(M, sh) * rfft2(K, sh), sh)[Rb:Rb + M.shape[0], Rb:Rb + M.shape[1]]
cnt = conv[pad:-pad, pad:-pad]
cntQ = np.rint(crop(cnt)).astype(np.float32)
zh_w += np.where(bgQ, cntQ / Nbg, 0).astype(np.float32)
zhao = zh_c / np.maximum(zh_w, 1e-12)[..., None]
scatter = sc_c
scatter_n = sc_c / np.maximum(sc_w, 1)[..., None]
alpha = np.clip(jf_w, 0, 1)[..., None]
fgc = jf_c / np.maximum(jf_w, 1e-12)[..., None]
bgc = jb_c / np.maximum(jb_w, 1e-12)[..., None]
jim = fgc * alpha + bgc * (1 - alpha)
# variant: fg over bg where bg field itself also normalised but total capped
np.savez_compressed(f'{WORK}/{S}_dense.npz', zh_w=zh_w, sc_w=sc_w, jf_w=jf_w, jb_w=jb_w)
for name, img in [('zhao', zhao), ('scatter', scatter), ('scatter_n', scatter_n), ('jim', jim)]:
    p = f'{WORK}/{S}_dense_{name}.exr'; write(p, img)
    print(S, name, psnr(p, S), flush=True)
