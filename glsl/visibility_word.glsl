// Reading the compute rasteriser's visibility words (splat_compute_main.glsl
// writes them: the eye depth's bits above the splat's index, the nearest
// the least). Included after a `visibility` buffer of uint64_t and a push
// block with `target_width` (words per row).

// The word of a target pixel no splat covers: the fill before the raster
// (src/passes/splat_compute.rs), beyond every splat's word.
const uint64_t NOTHING = ~uint64_t(0);

// The word of target pixel t.
uint64_t word_at(ivec2 t) {
    return visibility[uint(t.y) * pc.target_width + uint(t.x)];
}

// The index of a word's splat.
uint word_splat(uint64_t word) {
    return uint(word & 0xffffffffUL);
}

// The eye depth of a word's splat (+inf for NOTHING: no splat).
float word_depth(uint64_t word) {
    return word == NOTHING ? 1.0 / 0.0 : uintBitsToFloat(uint(word >> 32));
}
