// The 64-bit bins of the ray distribution buffer (src/passes/rdb.rs,
// `PackedBins`): one word per (tile pixel, bin), in the layout BIN_MAJOR
// sets (src/passes/kernel_sizes.rs): a pixel's bins side by side (a CPU
// device), or a plane of the tile's pixels per bin (a GPU: neighbouring
// invocations offer to and read neighbouring words); each word holding
//   tag (5 bits) | depth bits (31) | source index (28).
// An atomicMin keeps the smallest depth and, at that depth, the smallest
// source: what the two 32-bit passes keep. A word is filled in this use of
// the bins only if its tag is the use's; every other word is stale (the
// buffer is filled with ones, tag 31, when it is made and after 31 uses;
// uses count the tags down from 30), so the bins are never cleared per frame.
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_shader_atomic_int64 : require

uint64_t bin_word(uint tag, uint depth_bits, uint source) {
    return (uint64_t(tag) << 59) | (uint64_t(depth_bits) << 28) | uint64_t(source);
}

bool bin_filled(uint64_t word, uint tag) {
    return uint(word >> 59) == tag;
}

uint bin_source(uint64_t word) {
    return uint(word & 0xFFFFFFFul);
}

layout(constant_id = 6) const bool BIN_MAJOR = false;

// The word of bin `bin` (of `bins` a pixel) of tile pixel `t` in a tile of
// `size` pixels.
uint bin_index(int bin, int bins, ivec2 t, ivec2 size) {
    uint pixel = uint(t.y * size.x + t.x);
    return BIN_MAJOR ? uint(bin) * uint(size.x * size.y) + pixel : pixel * uint(bins) + uint(bin);
}
