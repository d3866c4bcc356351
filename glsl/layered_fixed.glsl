// Fixed-point sums of the layered method's spreading (DESIGN §6): a pixel's
// (r, g, b, a) as two 64-bit words, (r, g) and (b, a), each channel a
// signed 32-bit value with FRACTION_BITS fractional bits in one half of
// the word. Integer addition is associative, so the sums (of signed
// differences, then prefix sums) are the same in any order: the image is
// bitwise reproducible. Words add as integers modulo 2^64; a half is read
// back exactly when the channel's final value fits its 32 bits
// (|value| < 2^(31 - FRACTION_BITS)).
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_shader_atomic_int64 : require

// Mirrors FRACTION_BITS in src/passes/layered.rs.
const int FRACTION_BITS = 22;
const float ONE = float(1 << FRACTION_BITS);

ivec4 to_fixed(vec4 v) {
    return ivec4(round(v * ONE));
}

// (hi, lo) in fixed point as one word: hi * 2^32 + lo.
uint64_t pack(int hi, int lo) {
    return uint64_t((int64_t(hi) << 32) + int64_t(lo));
}

// The two channels of a word: lo from its low 32 bits, then hi from the rest.
vec2 unpack(uint64_t word) {
    int lo = int(uint(word & 0xFFFFFFFFul));
    int hi = int(uint((word - uint64_t(int64_t(lo))) >> 32));
    return vec2(float(hi), float(lo)) / ONE;
}
