// Shirley–Chiu concentric map between the square [−1, 1]² and the unit
// disk (DESIGN §5), mirrored from src/camera/tables.rs (`concentric_disk`,
// `concentric_square`); tests/shaders.rs checks that both sides agree.

// The square [−1, 1]² onto the unit disk, area-preserving.
vec2 concentric_disk(vec2 a) {
    if (a == vec2(0.0)) {
        return vec2(0.0);
    }
    const float quarter = 0.7853981633974483;
    float r;
    float theta;
    if (abs(a.x) > abs(a.y)) {
        r = a.x;
        theta = quarter * (a.y / a.x);
    } else {
        r = a.y;
        theta = 2.0 * quarter - quarter * (a.x / a.y);
    }
    return r * vec2(cos(theta), sin(theta));
}

// The inverse: a point of the unit disk back to the square.
vec2 concentric_square(vec2 u) {
    float r = length(u);
    if (r == 0.0) {
        return vec2(0.0);
    }
    const float four_over_pi = 1.2732395447351628;
    if (abs(u.x) >= abs(u.y)) {
        float s = u.x >= 0.0 ? 1.0 : -1.0;
        float theta = atan(s * u.y, s * u.x);
        return vec2(s * r, s * r * theta * four_over_pi);
    }
    float s = u.y >= 0.0 ? 1.0 : -1.0;
    float theta = atan(s * u.y, s * u.x);
    return vec2(s * r * (1.5707963267948966 - theta) * four_over_pi, s * r);
}
