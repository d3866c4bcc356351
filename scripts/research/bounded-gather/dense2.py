"""Dense evaluation of occlusion-limited scatter rules (all offsets, exact discrete).
V1 : K(P->Q) = [d <= r_P] if z_P <= z_Q else [d <= min(r_P, r_Q)], weight 1/N_P, unnormalised sum.
V1n: V1 / max(1, sum K w).
V5 : near-field sources (z_P < focus): [d <= r_P]; far-field sources: [d <= min(r_P, r_Q)]  (the split used by the tapped version)
V5n: V5 / max(1, sum w).
jimN: fg (z_P<z_Q) alpha-composited over bg field normalised; bg field weight = 1/N(min(rP,rQ)) instead of 1."""
import sys, time, numpy as np
from common import *
S = sys.argv[1]
rgb, z, coc, cam, bg, r, wN, zf = dense_inputs(S)
H, W = z.shape
f = cam['focus_distance']
near = zf < f
R = int(np.ceil(r[~bg].max()))
h, w = H - 2 * G, W - 2 * G
zQ = crop(zf); rQ = crop(r)
acc = {k: (np.zeros((h, w, 3), np.float32), np.zeros((h, w), np.float32)) for k in ['V1', 'V5', 'jf', 'jb']}
t0 = time.time()
offs = [(dy, dx) for dy in range(-R, R + 1) for dx in range(-R, R + 1) if dx * dx + dy * dy <= R * R]
def add(k, ww, cP):
    acc[k][1][...] += ww; acc[k][0][...] += ww[..., None] * cP
for dy, dx in offs:
    d = np.float32(np.sqrt(dx * dx + dy * dy))
    sl = (slice(G + dy, G + dy + h), slice(G + dx, G + dx + w))
    rP = r[sl]; zP = zf[sl]; cP = rgb[sl]; wP = wN[sl]; nP = near[sl]
    front = zP <= zQ
    limited = np.minimum(rP, rQ) >= d
    own = rP >= d
    add('V1', np.where(np.where(front, own, limited), wP, 0), cP)
    add('V5', np.where(np.where(nP, own, limited), wP, 0), cP)
    fr = zP < zQ
    add('jf', np.where(fr & own, wP, 0), cP)
    add('jb', np.where(~fr & limited, 1.0 / ncount(np.minimum(rP, rQ)), 0).astype(np.float32), cP)
print('loop', len(offs), time.time() - t0, flush=True)
outs = {}
for k in ['V1', 'V5']:
    c, s = acc[k]; outs[k] = c; outs[k + 'n'] = c / np.maximum(s, 1)[..., None]
a = np.clip(acc['jf'][1], 0, 1)[..., None]
outs['jimN'] = acc['jf'][0] / np.maximum(acc['jf'][1], 1e-12)[..., None] * a + acc['jb'][0] / np.maximum(acc['jb'][1], 1e-12)[..., None] * (1 - a)
np.savez_compressed(f'{WORK}/{S}_dense2_w.npz', **{k: acc[k][1] for k in acc})
for k, img in outs.items():
    p = f'{WORK}/{S}_dense2_{k}.exr'; write(p, img); print(S, k, psnr(p, S), flush=True)
