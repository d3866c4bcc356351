"""Tap-count model of the tapped J2 method (jtap.py) per scene: average taps per full-res pixel and time at 5 ns/tap/px."""
import numpy as np
from common import *
def cnt(R):
    n = int(np.ceil(R)); return sum(1 for y in range(-n, n + 1) for x in range(-n, n + 1) if x * x + y * y < R * R)
cfgs = [(3, 4, 3), (3, 4, 2), (2, 4, 3), (2, 4, 2), (3, 3, 3), (2, 3, 3), (2, 3, 2)]
for S in SCENES:
    rgb, z, coc, cam = load(S); f = cam['focus_distance']
    zc = crop(z); rc = crop(coc) / 2; fin = np.isfinite(zc); h, w = zc.shape
    nearsrc = crop(z < f)
    T = 16; th, tw = h // T, w // T
    tn = nearsrc[:th * T, :tw * T].reshape(th, T, tw, T).any((1, 3))
    tn = np.pad(tn, 1); tn = tn[:-2, :-2] | tn[1:-1, :-2] | tn[2:, :-2] | tn[:-2, 1:-1] | tn[1:-1, 1:-1] | tn[2:, 1:-1] | tn[:-2, 2:] | tn[1:-1, 2:] | tn[2:, 2:]
    neartile = np.zeros((h, w), bool); neartile[:th * T, :tw * T] = np.repeat(np.repeat(tn, T, 0), T, 1)
    def tileflag(src):
        t = src[:th * T, :tw * T].reshape(th, T, tw, T).any((1, 3)); t = np.pad(t, 1)
        t = t[:-2, :-2] | t[1:-1, :-2] | t[2:, :-2] | t[:-2, 1:-1] | t[1:-1, 1:-1] | t[2:, 1:-1] | t[:-2, 2:] | t[1:-1, 2:] | t[2:, 2:]
        o = np.zeros((h, w), bool); o[:th * T, :tw * T] = np.repeat(np.repeat(t, T, 0), T, 1); return o
    for B0, B, K in cfgs:
        # level-0 band only in 16x16 tiles (dilated by one) holding a source it needs: any finite source with r<B0 for
        # background receivers, a near-field source with r<B0 for finite receivers
        fsm = tileflag(fin & (rc < B0)); nsm = tileflag(nearsrc & (rc < B0))
        l0 = cnt(B0 + 0.7072) * (((~fin) & fsm) | (fin & nsm)).mean()
        lv = cnt(B + 0.5 + 0.7072) / 3
        small = fin & (rc < K + 0.5); big = fin & ~small
        ring = (1 + 4 * K * (K + 1)) * big.mean() + cnt(K + 0.5 + 0.7072) * small.mean()
        tot = l0 + lv + 5 + ring
        print(f'{S:7s} B0={B0} B={B} K={K}: L0 {l0:5.1f} levels {lv:5.1f} upsample 5 ring {ring:5.1f} -> {tot:5.1f} taps/px, ~{tot*h*w*5e-9*1e3:4.0f} ms at 5 ns')
