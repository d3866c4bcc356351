// The 64-bit bins of the ray distribution buffer (src/passes/rdb.rs,
// `PackedBins`): one word per (tile pixel, bin), pixel-major, holding
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
