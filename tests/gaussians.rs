//! 3D Gaussian scenes read from the reference code's PLY layout (issue 31,
//! item 1; docs/ARCHITECTURE.md, "3D Gaussian scenes"): activations, the
//! SH coefficients' order, every encoding, and bad files in one line.

mod common;

use std::path::Path;

use common::{assert_fails, assert_runs, scratch};
use pointlens::input::gaussians::load_gaussians;

/// One Gaussian's stored (not activated) values.
#[derive(Clone)]
struct Stored {
    xyz: [f32; 3],
    dc: [f32; 3],
    /// Channel-major, as stored: red's coefficients, green's, blue's.
    rest: Vec<f32>,
    opacity: f32,
    scale: [f32; 3],
    rot: [f32; 4],
}

/// Writes `gaussians` as a 3DGS PLY file (`format` binary_little_endian,
/// binary_big_endian or ascii), with `nx ny nz` after `x y z` as the
/// reference code writes them, leaving out the properties in `without`.
fn write(path: &Path, format: &str, gaussians: &[Stored], without: &[&str]) {
    let rest = gaussians[0].rest.len();
    let mut names: Vec<String> = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    names.extend((0..rest).map(|k| format!("f_rest_{k}")));
    names.extend(
        [
            "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
        ]
        .iter()
        .map(|s| s.to_string()),
    );
    let kept: Vec<usize> = (0..names.len())
        .filter(|&i| !without.contains(&names[i].as_str()))
        .collect();
    let mut out = format!(
        "ply\nformat {format} 1.0\nelement vertex {}\n",
        gaussians.len()
    );
    for &i in &kept {
        out += &format!("property float {}\n", names[i]);
    }
    out += "end_header\n";
    let mut bytes = out.into_bytes();
    for g in gaussians {
        let mut v: Vec<f32> = g.xyz.to_vec();
        v.extend([0.0, 0.0, 0.0]);
        v.extend(g.dc);
        v.extend(&g.rest);
        v.push(g.opacity);
        v.extend(g.scale);
        v.extend(g.rot);
        let v: Vec<f32> = kept.iter().map(|&i| v[i]).collect();
        match format {
            "ascii" => {
                let line: Vec<String> = v.iter().map(|x| format!("{x:e}")).collect();
                bytes.extend(line.join(" ").bytes());
                bytes.push(b'\n');
            }
            "binary_big_endian" => v.iter().for_each(|x| bytes.extend(x.to_be_bytes())),
            _ => v.iter().for_each(|x| bytes.extend(x.to_le_bytes())),
        }
    }
    std::fs::write(path, bytes).unwrap();
}

/// `n` Gaussians of SH degree `degree`, values from a fixed sequence.
fn scene(n: usize, degree: usize) -> Vec<Stored> {
    let mut state = 12345u32;
    let mut next = move || {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (state >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
    };
    let rest = 3 * ((degree + 1) * (degree + 1) - 1);
    (0..n)
        .map(|_| Stored {
            xyz: [next(), next(), next()],
            dc: [next(), next(), next()],
            rest: (0..rest).map(|_| next()).collect(),
            opacity: 4.0 * next(),
            scale: [next() - 3.0, next() - 3.0, next() - 3.0],
            rot: [next(), next(), next(), next()],
        })
        .collect()
}

#[test]
fn gaussians_are_read_with_the_reference_activations() {
    let dir = scratch("gaussians-read");
    for degree in 0..=3 {
        let stored = scene(50, degree);
        let path = dir.path().join(format!("d{degree}.ply"));
        write(&path, "binary_little_endian", &stored, &[]);
        let s = load_gaussians(&path).unwrap();
        assert_eq!(s.len(), 50);
        assert_eq!(s.sh_degree, degree as u32);
        let k = (degree + 1) * (degree + 1);
        assert_eq!(s.coefficients(), k);
        for (g, t) in stored.iter().enumerate() {
            assert_eq!(s.positions[g].to_array(), t.xyz);
            for a in 0..3 {
                assert_eq!(s.scales[g][a], t.scale[a].exp());
            }
            assert_eq!(s.opacities[g], 1.0 / (1.0 + (-t.opacity).exp()));
            let q = s.rotations[g];
            let norm = t.rot.iter().map(|v| v * v).sum::<f32>().sqrt();
            // rot_0 is w; x, y, z follow.
            for (got, want) in [q.w, q.x, q.y, q.z].iter().zip(t.rot) {
                assert!(
                    (got - want / norm).abs() < 1e-6,
                    "{q:?} against {:?}",
                    t.rot
                );
            }
            let sh = s.sh_of(g);
            for c in 0..3 {
                assert_eq!(sh[c], t.dc[c], "DC of channel {c}");
                for j in 1..k {
                    // f_rest is channel-major: channel c's coefficient j at
                    // c × (k − 1) + j − 1.
                    assert_eq!(sh[j * 3 + c], t.rest[c * (k - 1) + j - 1]);
                }
            }
        }
    }
}

#[test]
fn every_encoding_gives_the_same_scene() {
    let dir = scratch("gaussians-encodings");
    let stored = scene(40, 2);
    let read = |format: &str| {
        let path = dir.path().join(format!("{format}.ply"));
        write(&path, format, &stored, &[]);
        load_gaussians(&path).unwrap()
    };
    let le = read("binary_little_endian");
    for other in [read("binary_big_endian"), read("ascii")] {
        assert_eq!(other.positions, le.positions);
        assert_eq!(other.scales, le.scales);
        assert_eq!(other.rotations, le.rotations);
        assert_eq!(other.opacities, le.opacities);
        assert_eq!(other.sh, le.sh);
    }
}

#[test]
fn a_bad_gaussian_file_is_one_line() {
    let dir = scratch("gaussians-bad");
    let out = dir.path().join("none.png");
    let check = |stored: &[Stored], without: &[&str], phrase: &str| {
        let path = dir.path().join("bad.ply");
        write(&path, "binary_little_endian", stored, without);
        let p = path.to_str().unwrap();
        assert_fails(&["info", p], phrase, &out);
    };
    let good = scene(5, 1);
    check(
        &good,
        &["rot_3", "scale_1"],
        "without the properties scale_1, rot_3",
    );
    check(&good, &["f_rest_8"], "8 f_rest_* properties");
    let mut nan = good.clone();
    nan[3].opacity = f32::NAN;
    check(&nan, &[], "Gaussian 3: opacity is NaN (not finite)");
    let mut zero = good.clone();
    zero[1].rot = [0.0; 4];
    check(&zero, &[], "Gaussian 1: its rotation rot_0..3 is all zeros");
    let mut huge = good.clone();
    huge[2].scale[2] = 50.0;
    check(&huge, &[], "Gaussian 2: scale_2 = 50 overflows");
    // Truncated: the last Gaussian's bytes cut.
    let path = dir.path().join("cut.ply");
    write(&path, "binary_little_endian", &good, &[]);
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() - 10]).unwrap();
    assert_fails(&["info", path.to_str().unwrap()], "truncated", &out);
}

/// `info` describes a scene; `render` and `convert` say in one line that
/// they do not take it (yet).
#[test]
fn the_command_line_knows_a_gaussian_scene() {
    let dir = scratch("gaussians-cli");
    let path = dir.path().join("scene.ply");
    write(&path, "binary_little_endian", &scene(30, 3), &[]);
    let p = path.to_str().unwrap();
    let info = assert_runs(&["info", p]);
    let text = String::from_utf8_lossy(&info.stdout);
    assert!(text.contains("gaussians: 30\nsh_degree: 3\n"), "{text}");
    let png = dir.path().join("frame.png");
    assert_fails(
        &["render", p, "-o", png.to_str().unwrap()],
        "it holds 3D Gaussians",
        &png,
    );
    let copc = dir.path().join("scene.copc.laz");
    assert_fails(
        &["convert", p, "-o", copc.to_str().unwrap()],
        "it holds 3D Gaussians",
        &copc,
    );
}
