// The tiles of the area coverage's marking (src/passes/splat_compute.rs,
// AREA_TILE_PX): squares of AREA_TILE_PX × AREA_TILE_PX G-buffer pixels of
// a raster target, row by row from its corner. The compute raster flags
// every tile that a drawn splat's box, one target pixel past it, reaches
// (splat_compute_main.glsl); in a tile it leaves unflagged every word of
// every pixel's window (its block and the ring of target pixels around
// it) is background, and the marking resolve (gbuffer_resolve_vis.glsl)
// reads none of them.
const int AREA_TILE_PX = 8;

// Tiles per row of a target `width_px` G-buffer pixels wide.
int area_tiles_per_row(int width_px) {
    return (width_px + AREA_TILE_PX - 1) / AREA_TILE_PX;
}
