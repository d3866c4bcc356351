// The pixel centres of a CoC disk (DESIGN §4, §6): the integer offsets
// (dx, dy) with dx² + dy² ≤ (c/2)², found exactly in integers. Shared by the
// fast gather's area weights and the layered method's spreading; mirrored by
// `reference::disk_half_width` and `reference::disk_pixel_count`.

// Largest dx ≥ 0 with dx² + dy² ≤ r2 (r2 = (c/2)², |dy| ≤ floor(c/2)).
int disk_half_width(float r2, int dy) {
    int dx = int(floor(sqrt(max(r2 - float(dy * dy), 0.0))));
    while (float(dx * dx + dy * dy) > r2) { --dx; }
    while (float((dx + 1) * (dx + 1) + dy * dy) <= r2) { ++dx; }
    return dx;
}

// Pixel centres within distance c/2 of a pixel centre (at least 1).
float disk_pixel_count(float c) {
    float r2 = 0.25 * c * c;
    int r = int(floor(0.5 * c));
    float n = 0.0;
    for (int dy = -r; dy <= r; ++dy) {
        n += float(2 * disk_half_width(r2, dy) + 1);
    }
    return max(n, 1.0);
}
