// The block tree of the fast gather (src/passes/fast.rs, `FastTree`):
// level l holds blocks of 2^l × 2^l G-buffer pixels, row by row, the
// levels TREE_LEAF_LEVEL to pc.levels one after another. The rows of every
// level are padded to a G-buffer of pc.padded pixels (the extent rounded
// up to a multiple of 2^levels), so that level l has (padded >> l) blocks
// per axis and starts after (N / 4^(LEAF - 1) - N / 4^(l - 1)) / 3 blocks,
// N = padded.x · padded.y (an integer sum of a geometric series). A block
// holds the sum of its pixels' weighted colors (w · rgba), the sum of their
// weights, and the bounds of their eye depths and CoCs: what lets the
// gather take or leave all of a block's pixels at once. Blocks of the
// padding beyond the extent are never written nor read.

// The most levels a tree has (mirrors TREE_LEVELS_MAX in src/passes/fast.rs).
const int TREE_LEVELS_MAX = 14;
// The smallest gather radius (px) taken by blocks; below it, pixel by pixel
// (mirrors TREE_MIN_RADIUS_PX in src/passes/fast.rs).
const int TREE_MIN_RADIUS = 16;
// The lowest level stored: a block of it that can be neither taken nor
// left whole is gathered pixel by pixel (mirrors TREE_LEAF_LEVEL in
// src/passes/fast.rs).
const int TREE_LEAF_LEVEL = 2;

// The index of block b of level l >= TREE_LEAF_LEVEL in a tree over a
// padded G-buffer of `padded` pixels.
uint tree_index(ivec2 padded, int l, ivec2 b) {
    uint pixels = uint(padded.x) * uint(padded.y);
    uint before = ((pixels >> (2 * (TREE_LEAF_LEVEL - 1))) - (pixels >> (2 * (l - 1)))) / 3u;
    return before + uint(b.y) * uint(padded.x >> l) + uint(b.x);
}

// Blocks per axis at level l over the G-buffer itself (without padding).
ivec2 tree_level_size(ivec2 extent, int l) {
    return (extent + (1 << l) - 1) >> l;
}
