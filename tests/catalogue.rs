//! The catalogue of bad input (issue 17): one table, one row per case,
//! each with the words its error must hold. Every case must end with a
//! non-zero exit status, exactly one line on stderr, no panic, no output
//! file created where there was none, and an existing output left as it
//! was. A new input format, flag or command adds its rows here.
//!
//! Rows name files by placeholders: `{bunny}` the bundled PLY, `{fuzz}`
//! the inputs fuzzing found (`tests/data/fuzz`), `{dir}` the
//! test's folder (where the bad files below are written), `{out}` the
//! output the case must not touch.

mod common;

use std::path::Path;

use common::{file_names, pointlens, root, scratch};

/// What the output path of a case is, for the "no file, old file intact"
/// checks.
#[derive(Clone, Copy, PartialEq)]
enum Output {
    /// `{out}` is a file path: checked missing, then with an old file.
    File,
    /// The case's output cannot hold a file (a folder, a missing folder, a
    /// path under /proc): only "nothing created".
    Unwritable,
    /// The command writes no file (`info`, `compare` without `--diff`).
    None,
}

struct Case {
    args: &'static str,
    /// Words the one line must hold (case-sensitive).
    phrase: &'static str,
    output: Output,
}

const fn case(args: &'static str, phrase: &'static str) -> Case {
    Case {
        args,
        phrase,
        output: Output::File,
    }
}

const fn unwritable(args: &'static str, phrase: &'static str) -> Case {
    Case {
        args,
        phrase,
        output: Output::Unwritable,
    }
}

const fn no_output(args: &'static str, phrase: &'static str) -> Case {
    Case {
        args,
        phrase,
        output: Output::None,
    }
}

/// Small frames on lavapipe for every render row.
const R: &str = "--width 16 --height 12 --device llvmpipe";

/// The table. Arguments are split on spaces after the placeholders are
/// filled in (no argument holds a space).
fn catalogue() -> Vec<Case> {
    vec![
        // PLY input.
        case("render {dir}/no-such.ply -o {out} R", "no-such.ply"),
        case("render {dir}/empty.ply -o {out} R", "empty.ply"),
        case("render {dir}/not-ply.ply -o {out} R", "not-ply.ply"),
        case(
            "render {dir}/no-end-header.ply -o {out} R",
            "no-end-header.ply",
        ),
        case("render {dir}/count-lies.ply -o {out} R", "count-lies.ply"),
        case(
            "render {dir}/binary-truncated.ply -o {out} R",
            "binary-truncated.ply",
        ),
        case("render {dir}/no-vertex.ply -o {out} R", "no-vertex.ply"),
        case("render {dir}/no-x.ply -o {out} R", "no-x.ply"),
        case(
            "render {dir}/middle-endian.ply -o {out} R",
            "middle-endian.ply",
        ),
        case("render {dir}/huge-count.ply -o {out} R", "huge-count.ply"),
        case("render {dir}/all-nan.ply -o {out} R", "all-nan.ply"),
        case("render {dir} -o {out} R", "{dir}"),
        // Camera files.
        case(
            "render {bunny} -o {out} R --camera {dir}/no-such.json",
            "no-such.json",
        ),
        case(
            "render {bunny} -o {out} R --camera {dir}/not-json.json",
            "not-json.json",
        ),
        case(
            "render {bunny} -o {out} R --camera {dir}/fovy-0.json",
            "fovy_deg",
        ),
        case(
            "render {bunny} -o {out} R --camera {dir}/fovy-180.json",
            "fovy_deg",
        ),
        case(
            "render {bunny} -o {out} R --camera {dir}/focus-negative.json",
            "focus_distance",
        ),
        case(
            "render {bunny} -o {out} --device llvmpipe --camera {dir}/width-0.json",
            "width",
        ),
        case(
            "render {bunny} -o {out} R --camera {dir}/eye-is-target.json",
            "eye",
        ),
        case(
            "render {bunny} -o {out} R --camera {dir}/up-parallel.json",
            "up",
        ),
        case(
            "render {bunny} -o {out} R --camera {dir}/aperture-negative.json",
            "aperture_radius",
        ),
        case(
            "render {bunny} -o {out} R --camera {dir}/f-number-alone.json",
            "focal_length_mm",
        ),
        case(
            "render {bunny} -o {out} R --camera {dir}/no-eye.json",
            "eye",
        ),
        case(
            "render {bunny} -o {out} R --camera {dir}/two-sensors.json",
            "sensor_width_mm",
        ),
        case(
            "render {bunny} -o {out} R --camera {dir}/eye-text.json",
            "eye-text.json",
        ),
        case(
            "render {bunny} -o {out} R --camera {dir}/origin-with-file.json",
            "origin",
        ),
        // Every flag's range.
        case("render {bunny} -o {out} R --ssaa 0", "--ssaa"),
        case("render {bunny} -o {out} R --ssaa 17", "--ssaa"),
        case("render {bunny} -o {out} R --rdb-bins 1", "--rdb-bins"),
        case("render {bunny} -o {out} R --rdb-bins 17", "--rdb-bins"),
        case("render {bunny} -o {out} R --layers 0", "--layers"),
        case("render {bunny} -o {out} R --layers 9", "--layers"),
        case("render {bunny} -o {out} R --samples 0", "--samples"),
        case(
            "render {bunny} -o {out} R --samples-per-pass 0",
            "--samples-per-pass",
        ),
        case(
            "render {bunny} -o {out} R --rdb-memory-mb 0",
            "--rdb-memory-mb",
        ),
        case("render {bunny} -o {out} R --lod-px -1", "--lod-px"),
        case("render {bunny} -o {out} R --lod-px NaN", "--lod-px"),
        case("render {bunny} -o {out} R --lod-px 1e9", "--lod-px"),
        case("render {bunny} -o {out} R --lod-blur 0", "--lod-blur"),
        case(
            "render {bunny} -o {out} R --lod-blur 2 --lod-px 0",
            "--lod-blur",
        ),
        case("render {bunny} -o {out} R --splat-size 0", "--splat-size"),
        case("render {bunny} -o {out} R --splat-px -1", "--splat-px"),
        case(
            "render {bunny} -o {out} R --background 2,0,0",
            "--background",
        ),
        case("render {bunny} -o {out} R --background red", "--background"),
        case(
            "render {bunny} -o {out} R --method magic",
            "available methods",
        ),
        case(
            "render {bunny} -o {out} R --focus-pixel 100,100",
            "--focus-pixel",
        ),
        // Beyond the device's images a frame renders in tiles
        // (tests/tiles.rs); beyond these sizes it is refused.
        case(
            "render {bunny} -o {out} --width 100000 --height 8 --device llvmpipe",
            "65536",
        ),
        case(
            "render {bunny} -o {out} --width 40000 --height 40000",
            "2^30",
        ),
        case("render {bunny} -o {out} R --tile-px 0", "--tile-px"),
        case("render {bunny} -o {out} R --fovy-deg 200", "fovy_deg"),
        case("render {bunny} -o {out} R --eye 1,2", "--eye"),
        case("render {bunny} -o {out} R --eye 1,2,inf", "--eye"),
        case(
            "render {bunny} -o {out} R --focus-distance 0",
            "focus_distance",
        ),
        case("render {bunny} -o {out} R --f-number 2", "focal_length_mm"),
        case(
            "render {bunny} -o {out} R --focal-length-mm 50 --sensor-width-mm -36",
            "sensor_width_mm",
        ),
        case(
            "render {bunny} -o {out} R --units-per-mm 0 --f-number 2 --focal-length-mm 50",
            "units_per_mm",
        ),
        case(
            "render {bunny} -o {out} R --coordinates file --origin 1,2",
            "--origin",
        ),
        case(
            "render {bunny} -o {out} --width 16 --height 12 --device no-such-gpu",
            "no-such-gpu",
        ),
        case("render {bunny} -o {out} R --frobnicate", "--frobnicate"),
        case("render {bunny} -o {out} R --passes z", "EXR"),
        case(
            "render {bunny} -o {out} R --aperture-radius -0.1",
            "aperture_radius",
        ),
        case("render {bunny} -o {out} R --up 0,0,0", "up"),
        case(
            "render {bunny} -o {out} R --focal-length-mm 50 --sensor-height-mm 0",
            "sensor_height_mm",
        ),
        case(
            "render {bunny} -o {out} R --focal-length-mm -50",
            "focal_length_mm",
        ),
        case(
            "render {bunny} -o {out} R --fast-weights heavy",
            "--fast-weights",
        ),
        case(
            "render {bunny} -o {out} R --fast-window round",
            "--fast-window",
        ),
        // The paper's rule's options without the paper's rule: the
        // default two-field gather would ignore them.
        case(
            "render {bunny} -o {out} R --method fast --fast-weights uniform",
            "--fast-gather tree",
        ),
        case(
            "render {bunny} -o {out} R --method fast --fast-window fixed",
            "--fast-gather tree",
        ),
        // A method's option with another method cannot act: refused, by
        // one rule for every such flag (options::METHOD_FLAGS).
        case(
            "render {bunny} -o {out} R --fast-weights uniform",
            "--fast-weights acts on --method fast only, not layered",
        ),
        case(
            "render {bunny} -o {out} R --method accum --rdb-bins 5",
            "--rdb-bins acts on --method rdb only, not accum",
        ),
        case(
            "render {bunny} -o {out} R --method fast --samples 64",
            "--samples acts on --method accum only, not fast",
        ),
        case(
            "render {bunny} -o {out} R --method rdb --layers 3",
            "--layers acts on --method layered only, not rdb",
        ),
        case("render {bunny} -o {out} R --rdb-mode corners", "--rdb-mode"),
        case("render {bunny} -o {out} R --rdb-atomics 16", "--rdb-atomics"),
        case("render {bunny} -o {out} R --width 0", "width"),
        case("render {bunny} -o {out} R --height -3", "--height"),
        case(
            "render {bunny} -o {out} R --timings-json {dir}/missing/t.json",
            "missing",
        ),
        case(
            "render {dir}/count-1e12.laz -o {out} R",
            "declares 1000000000000 points",
        ),
        case(
            "render {dir}/count-1e15.laz -o {out} R",
            "which this 4368-byte file cannot hold",
        ),
        no_output("info {dir}/count-1e15.laz", "a wrong point count"),
        // Cameras beyond ±1e18 name what is out of range (they used to
        // say "up is parallel to the view direction").
        case("render {bunny} -o {out} R --eye 1e20,0,0", "eye: [100000000000000000000, 0, 0] is beyond"),
        case("render {bunny} -o {out} R --target 0,-1e20,0", "target: [0, -100000000000000000000, 0] is beyond"),
        case("render {bunny} -o {out} R --fovy-deg 1e-30", "to fit the cloud's extent in a 1e-30° field of view"),
        case(
            "render {bunny} -o {out} R --focal-length-mm 1e30 --sensor-height-mm 24",
            "field of view; widen it",
        ),
        case(
            "render {bunny} -o {dir}/s_%04d.png R --path {dir}/keyframe-1e308.json",
            "eye: [inf, 0, 0] is beyond",
        ),
        // synth checks the disk before writing (it used to write a 25.8 GB
        // temporary for this count before anything stopped it).
        case(
            "synth --points 18446744073709551615 -o {dir}/big.ply",
            "the disk has",
        ),
        case("synth --points 10000000000000 -o {dir}/big.laz", "need at least 80000.0 GB"),
        case("synth --lights 100 -o {dir}/lights.laz", "--lights is written as .ply"),
        // Eye-dome lighting.
        case("render {bunny} -o {out} R --edl 1 --method accum", "accum averages"),
        // Refused before the file is read: a missing file is not named.
        case(
            "render {dir}/no-such.ply -o {out} R --edl 1 --method accum",
            "accum averages",
        ),
        // Area coverage where it cannot act, before the file is read.
        case(
            "render {dir}/no-such.ply -o {out} R --coverage area --method accum",
            "not accum",
        ),
        case(
            "render {dir}/no-such.ply -o {out} R --coverage area --raster sprites",
            "not the sprite raster",
        ),
        // --samples-per-pass draws through the sprites.
        case(
            "render {dir}/no-such.ply -o {out} R --coverage area --samples-per-pass 4",
            "not the sprite raster",
        ),
        case(
            "bench --methods pinhole,accum4 --coverage area --models synthetic --points 10",
            "not accum",
        ),
        case(
            "render {bunny} -o {out} R --coverage area --splat-shape disc",
            "not --splat-shape disc",
        ),
        case("render {bunny} -o {out} R --coverage exact", "--coverage"),
        case("render {bunny} -o {out} R --edl -1", "--edl strength"),
        case("render {bunny} -o {out} R --edl 1,2,3", "STRENGTH[,RADIUS_PX]"),
        case("render {bunny} -o {out} R --edl 1,64", "--edl radius"),
        case("render {bunny} -o {out} R --color bogus", "--color"),
        // The timings would replace the image.
        case(
            "render {bunny} -o {out} R --timings-json {out}",
            "is the image of frame",
        ),
        case(
            "render {bunny} -o {out} R --origin 1,2,nan",
            "--origin",
        ),
        case("render {bunny} -o {out} R --passes q", "--passes"),
        // Output paths.
        unwritable("render {bunny} -o {dir}/missing/o.png R", "missing"),
        unwritable("render {bunny} -o {dir} R", "{dir}"),
        unwritable(
            "render {bunny} -o /proc/pointlens-catalogue.png R",
            "pointlens-catalogue.png",
        ),
        case(
            "render {bunny} -o {dir}/o.jpg R",
            "unsupported output format",
        ),
        case("render {bunny} -o {dir}/o R", "no extension"),
        // Sequences.
        case(
            "render {bunny} -o {dir}/s_%04d.png R --frames 0",
            "--frames",
        ),
        case("render {bunny} -o {out} R --frames 3", "frame number"),
        case(
            "render {bunny} -o {dir}/s_%04d.png R",
            "one frame to render",
        ),
        case(
            "render {bunny} -o {dir}/s_%s.png R --frames 2",
            "not a frame number pattern",
        ),
        case(
            "render {bunny} -o {dir}/s_%04d.png R --frames 3 --frame-range 2-5",
            "outside",
        ),
        case(
            "render {bunny} -o {dir}/s_%04d.png R --frames 3 --frame-range 3-2",
            "--frame-range",
        ),
        case(
            "render {bunny} -o {dir}/s_%04d.png R --path {dir}/decreasing.json",
            "must increase",
        ),
        case(
            "render {bunny} -o {dir}/s_%04d.png R --path {dir}/not-json.json",
            "not-json.json",
        ),
        // A path sets each frame's camera: the motions of --frames beside
        // it were once ignored without a word.
        case(
            "render {bunny} -o {dir}/s_%04d.png R --path {dir}/decreasing.json --orbit 90",
            "--orbit",
        ),
        case(
            "render {bunny} -o {dir}/s_%04d.png R --path {dir}/decreasing.json --focus-from 1 --focus-to 2",
            "--focus-from",
        ),
        case(
            "render {bunny} -o {dir}/s_%04d.png R --path {dir}/decreasing.json --aperture-from 0 --aperture-to 1",
            "--aperture-from",
        ),
        case(
            "render {bunny} -o {dir}/s_%04d.png R --frames 4000000000",
            "more than a sequence may have",
        ),
        case(
            "render {bunny} -o {dir}/s_%04d.png R --path {dir}/far-keyframe.json",
            "largest frame number",
        ),
        case(
            "render {bunny} -o {dir}/s_%04d.png R --frames 3 --frame-range two",
            "--frame-range",
        ),
        case(
            "render {bunny} -o {dir}/s_%04d.png R --frames 3 --orbit inf",
            "--orbit",
        ),
        case(
            "render {bunny} -o {dir}/s_%04d.png R --frames 3 --focus-from 0 --focus-to 1",
            "--focus-from",
        ),
        case(
            "render {bunny} -o {dir}/s_%04d.png R --frames 3 --aperture-from -1 --aperture-to 0",
            "--aperture-from",
        ),
        case(
            "render {bunny} -o {dir}/s_%04d.png R --orbit 90",
            "--frames",
        ),
        // Numbered folders: d_1 exists, d_2 does not.
        case(
            "render {bunny} -o {dir}/d_%d/f.png R --frames 2",
            "no directory {dir}/d_2",
        ),
        // LAS / LAZ.
        case("render {dir}/truncated.las -o {out} R", "truncated.las"),
        case("render {dir}/record-length.las -o {out} R", "record length"),
        case("render {dir}/count-lies.las -o {out} R", "count-lies.las"),
        case(
            "render {dir}/chunk-table-outside.laz -o {out} R",
            "chunk-table-outside.laz",
        ),
        case("render {dir}/not-las.las -o {out} R", "not-las.las"),
        // Found by fuzzing (docs/FUZZING.md): chunk entries whose byte
        // counts overflow made the LAZ decompressor abort.
        case(
            "render {fuzz}/chunk-entries-overflow.laz -o {out} R",
            "its chunks hold",
        ),
        no_output(
            "info {fuzz}/chunk-entries-overflow.laz",
            "corrupt LAZ chunk table",
        ),
        // LAZ items that do not make the header's record length: an
        // assertion in the decompressor.
        case(
            "render {fuzz}/items-record-mismatch.laz -o {out} R",
            "the LAZ items make records of",
        ),
        // A fixed chunk size of 4 billion points: the decompressor asked
        // for 111 GB.
        case(
            "render {fuzz}/huge-chunk-size.laz -o {out} R",
            "chunks of 4278240080 points",
        ),
        no_output(
            "info {fuzz}/huge-chunk-size.laz",
            "huge-chunk-size.laz",
        ),
        // GPS times that switch sequences again and again: the `laz` crate
        // decodes a switch by calling itself, and overflowed its stack
        // (found by fuzzing `copc`; input::laz_gps). Render and info of
        // the COPC file skip its GPS times (tests/laz_gps.rs).
        case(
            "render {dir}/gps-switches.laz -o {out} R",
            "switches between time sequences",
        ),
        no_output(
            "info {dir}/gps-switches.laz",
            "switches between time sequences",
        ),
        case(
            "convert {dir}/gps-switches.laz -o {dir}/gps.copc.laz",
            "switches between time sequences",
        ),
        case(
            "convert {dir}/gps-switches.copc.laz -o {dir}/gps.copc.laz",
            "switches between time sequences",
        ),
        // compare.
        no_output("compare {dir}/no-such.png {bunny_png}", "no-such.png"),
        no_output("compare {bunny_png} {dir}/small.png", "size"),
        no_output("compare {bunny_png} {dir}/not-ply.ply", "not-ply.ply"),
        case(
            "compare {bunny_png} {bunny_png} --diff {dir}/d.jpg",
            "unsupported output format",
        ),
        // bench --from-json.
        no_output("bench --from-json {dir}/no-such.json", "no-such.json"),
        no_output(
            "bench --from-json {dir}/not-json.json",
            "not a bench report",
        ),
        no_output("bench --from-json {dir}/fovy-0.json", "not a bench report"),
        no_output(
            "bench --methods magic --models bunny --width 8 --height 8 --runs 1",
            "magic",
        ),
        no_output(
            "bench --runs 0 --models bunny --methods pinhole --width 8 --height 8",
            "--runs",
        ),
        no_output(
            "bench --ssaa 0 --models bunny --methods pinhole --width 8 --height 8",
            "--ssaa",
        ),
        no_output(
            "bench --lod-px 1,-1 --models bunny --methods pinhole --width 8 --height 8",
            "--lod-px",
        ),
        no_output(
            "bench --models {dir}/no-such.ply --methods pinhole --width 8 --height 8",
            "no-such.ply",
        ),
        no_output(
            "bench --models synthetic --points 0 --methods pinhole --width 8 --height 8",
            "--points",
        ),
        unwritable(
            "bench --models bunny --methods pinhole --width 8 --height 8 --runs 1 --json {dir}/missing/b.json",
            "missing",
        ),
        unwritable(
            "bench --models bunny --methods pinhole --width 8 --height 8 --runs 1 --csv {dir}/missing/b.csv",
            "missing",
        ),
        case(
            "bench --models bunny --methods pinhole --width 8 --height 8 --runs 1 --chart {dir}/c.jpg",
            "c.jpg",
        ),
        // info.
        no_output("info {dir}/no-such.ply", "no-such.ply"),
        no_output("info {dir}/count-lies.ply", "count-lies.ply"),
        // Some of a 3D Gaussian's properties but not all: a broken Gaussian
        // file, not a cloud of white points.
        case(
            "render {dir}/gaussian-no-opacity.ply -o {out} R",
            "without the properties opacity",
        ),
        no_output(
            "info {dir}/gaussian-no-opacity.ply",
            "without the properties opacity",
        ),
    ]
}

/// Writes the bad inputs the rows name into `dir`.
fn write_inputs(dir: &Path) {
    let w = |name: &str, bytes: &[u8]| std::fs::write(dir.join(name), bytes).unwrap();
    let ascii = |header: &str, body: &str| {
        format!("ply\nformat ascii 1.0\n{header}end_header\n{body}").into_bytes()
    };
    let xyz = "element vertex 2\nproperty float x\nproperty float y\nproperty float z\n";
    w("empty.ply", b"");
    let gaussian: String = [
        "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "scale_0", "scale_1",
    ]
    .iter()
    .chain(&["scale_2", "rot_0", "rot_1", "rot_2", "rot_3"])
    .map(|p| format!("property float {p}\n"))
    .collect();
    w(
        "gaussian-no-opacity.ply",
        &ascii(
            &format!("element vertex 1\n{gaussian}"),
            "0 0 0 0.5 0.5 0.5 -3 -3 -3 1 0 0 0\n",
        ),
    );
    w("not-ply.ply", b"hello, not a point cloud\n");
    w(
        "no-end-header.ply",
        b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\n",
    );
    w(
        "count-lies.ply",
        &ascii(&xyz.replace("vertex 2", "vertex 1000"), "0 0 0\n1 1 1\n"),
    );
    let mut binary = b"ply\nformat binary_little_endian 1.0\n".to_vec();
    binary.extend(xyz.replace("vertex 2", "vertex 100").as_bytes());
    binary.extend(b"end_header\n");
    binary.extend([0u8; 30]);
    w("binary-truncated.ply", &binary);
    w(
        "no-vertex.ply",
        &ascii(
            "element face 0\nproperty list uchar int vertex_indices\n",
            "",
        ),
    );
    w(
        "no-x.ply",
        &ascii(
            "element vertex 1\nproperty float y\nproperty float z\n",
            "0 0\n",
        ),
    );
    w(
        "middle-endian.ply",
        b"ply\nformat binary_middle_endian 1.0\nelement vertex 1\nproperty float x\nend_header\n",
    );
    w(
        "huge-count.ply",
        &ascii(&xyz.replace("vertex 2", "vertex 1000000000000"), "0 0 0\n"),
    );
    w("all-nan.ply", &ascii(xyz, "nan nan nan\nnan 0 nan\n"));
    // Camera files.
    let cam = |extra: &str| {
        format!(
            r#"{{"width": 16, "height": 12, "eye": [0, 0.1, 0.3], "target": [0, 0.1, 0],
                "fovy_deg": 40, "aperture_radius": 0.01, "focus_distance": 0.3 {extra}}}"#
        )
    };
    w("not-json.json", b"{ this is not json");
    w(
        "fovy-0.json",
        cam(r#", "fovy_deg": 0"#)
            .replace(r#""fovy_deg": 40,"#, "")
            .as_bytes(),
    );
    w("fovy-180.json", cam("").replace("40", "180").as_bytes());
    w(
        "focus-negative.json",
        cam("").replace("0.3 }", "-1 }").as_bytes(),
    );
    w(
        "width-0.json",
        cam("")
            .replace(r#""width": 16"#, r#""width": 0"#)
            .as_bytes(),
    );
    w(
        "eye-is-target.json",
        cam("").replace("[0, 0.1, 0.3]", "[0, 0.1, 0]").as_bytes(),
    );
    w("up-parallel.json", cam(r#", "up": [0, 0, 1]"#).as_bytes());
    w(
        "aperture-negative.json",
        cam("").replace("0.01", "-0.01").as_bytes(),
    );
    w(
        "f-number-alone.json",
        cam("")
            .replace(r#""aperture_radius": 0.01"#, r#""f_number": 2"#)
            .as_bytes(),
    );
    w(
        "no-eye.json",
        cam("").replace(r#""eye": [0, 0.1, 0.3],"#, "").as_bytes(),
    );
    w(
        "two-sensors.json",
        cam(r#", "focal_length_mm": 50, "sensor_width_mm": 36, "sensor_height_mm": 24"#)
            .replace(r#""fovy_deg": 40,"#, "")
            .as_bytes(),
    );
    w(
        "eye-text.json",
        cam("").replace("[0, 0.1, 0.3]", r#""here""#).as_bytes(),
    );
    w(
        "origin-with-file.json",
        cam(r#", "coordinates": "file", "origin": [1, 2, 3]"#).as_bytes(),
    );
    w(
        "decreasing.json",
        br#"{"keyframes": [{"frame": 3}, {"frame": 2}]}"#,
    );
    w(
        "keyframe-1e308.json",
        br#"{"keyframes": [{"frame": 1, "eye": [0, 0, 1]}, {"frame": 2, "eye": [1e308, 0, 0]}]}"#,
    );
    std::fs::create_dir_all(dir.join("d_1")).unwrap();
    w(
        "far-keyframe.json",
        br#"{"keyframes": [{"frame": 1}, {"frame": 4294967295}]}"#,
    );
    // LAS / LAZ, from the bundled tile and the COPC test file. Header
    // fields (LAS 1.2+): offset to point data at 96 (u32), record length at
    // 105 (u16), legacy point count at 107 (u32).
    let las = std::fs::read(root().join("data/autzen_trim.las")).unwrap();
    w("truncated.las", &las[..las.len() / 2]);
    let mut record = las.clone();
    record[105..107].copy_from_slice(&20u16.to_le_bytes());
    w("record-length.las", &record);
    let mut lying = las.clone();
    lying[107..111].copy_from_slice(&1_000_000u32.to_le_bytes());
    w("count-lies.las", &lying);
    w("not-las.las", b"LASF but not really");
    let laz = std::fs::read(root().join("tests/data/autzen.copc.laz")).unwrap();
    let data = u32::from_le_bytes(laz[96..100].try_into().unwrap()) as usize;
    let mut table = laz.clone();
    table[data..data + 8].copy_from_slice(&(laz.len() as i64 + 1_000_000).to_le_bytes());
    w("chunk-table-outside.laz", &table);
    // LAS 1.4's 64-bit point count (at 247) beyond any file: the `las`
    // crate's seek past the records failed as "Invalid argument".
    for (name, count) in [
        ("count-1e12.laz", 1_000_000_000_000u64),
        ("count-1e15.laz", 1_000_000_000_000_000),
    ] {
        let mut huge = laz.clone();
        huge[247..255].copy_from_slice(&count.to_le_bytes());
        w(name, &huge);
    }
    // GPS-time data whose codes switch between LASzip's time sequences
    // 100,000 times for one point (16 bytes): point by point (format 1),
    // and layered (PDAL's COPC file, its root node's GPS-time layer).
    common::craft::laz_gps_switches(&dir.join("gps-switches.laz"), 100_000);
    let pdal = std::fs::read(root().join("tests/data/pdal-1.2-with-color.copc.laz")).unwrap();
    w(
        "gps-switches.copc.laz",
        &common::craft::copc_gps_switches(&pdal, 100_000),
    );
    // A PNG smaller than the bunny's.
    pointlens::image_io::write_image(
        &pointlens::image_io::LinearImage::new(4, 3, [0.5; 4]),
        &dir.join("small.png"),
    )
    .unwrap();
}

#[test]
fn every_bad_input_fails_with_one_clear_line_and_touches_no_output() {
    let dir = scratch("catalogue");
    write_inputs(&dir);
    let out = dir.join("out.png");
    let fill = |s: &str| {
        s.replace(" R", &format!(" {R}"))
            .replace(
                "{bunny_png}",
                &root().join("docs/bunny.png").display().to_string(),
            )
            .replace(
                "{bunny}",
                &root().join("data/bunny_colored.ply").display().to_string(),
            )
            .replace(
                "{fuzz}",
                &root().join("tests/data/fuzz").display().to_string(),
            )
            .replace("{out}", &out.display().to_string())
            .replace("{dir}", &dir.display().to_string())
    };
    let cases = catalogue();
    assert!(cases.len() >= 50, "the catalogue has {} cases", cases.len());
    let mut failures = Vec::new();
    for case in &cases {
        let args = fill(case.args);
        let argv: Vec<&str> = args.split(' ').collect();
        let phrase = fill(case.phrase);
        // Where the case writes: its -o, or --diff's file; for a frame
        // pattern, the first frame's file.
        let target = argv
            .iter()
            .position(|a| *a == "-o" || *a == "--diff")
            .map(|i| {
                Path::new(&argv[i + 1].replace("%04d", "0001").replace("%d", "1")).to_path_buf()
            });
        let runs: &[bool] = match (case.output, &target) {
            (Output::File, Some(_)) => &[false, true],
            _ => &[false],
        };
        for &existing in runs {
            let t = target.as_ref().filter(|_| case.output == Output::File);
            if let Some(t) = t {
                let _ = std::fs::remove_file(t);
                if existing {
                    std::fs::write(t, b"old").unwrap();
                }
            }
            let before = file_names(&dir);
            let o = pointlens(&argv);
            let err = String::from_utf8_lossy(&o.stderr).into_owned();
            let mut problems = Vec::new();
            if o.status.success() {
                problems.push("succeeded".to_string());
            }
            if err.trim_end().lines().count() != 1 {
                problems.push("not one line on stderr".to_string());
            }
            if err.contains("panicked") {
                problems.push("panicked".to_string());
            }
            if !err.contains(&phrase) {
                problems.push(format!("lacks '{phrase}'"));
            }
            if let (Some(t), true) = (t, existing) {
                if std::fs::read(t).ok().as_deref() != Some(b"old") {
                    problems.push("changed the existing output".into())
                }
            }
            // Nothing new in the folder: no output (whatever its name: a
            // frame of a pattern, a report), no temporary file.
            let created: Vec<String> = file_names(&dir)
                .into_iter()
                .filter(|n| !before.contains(n))
                .collect();
            if !created.is_empty() {
                problems.push(format!("created {created:?}"));
            }
            if let Some(t) = t {
                let _ = std::fs::remove_file(t);
            }
            if !problems.is_empty() {
                failures.push(format!(
                    "{} (existing output: {existing}): {}\n    stderr: {}",
                    case.args,
                    problems.join(", "),
                    err.trim_end()
                ));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} cases failed:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
}

#[test]
fn degenerate_clouds_render_or_fail_clearly() {
    // One point and identical points render (an image of the asked size);
    // coordinates of ±1e30 (squares beyond f32) and beyond f32 (as float
    // and as double properties) fail with one line naming the point and no
    // file.
    let dir = scratch("catalogue-degenerate");
    let ply = |ty: &str, rows: &[&str]| {
        let mut s = format!(
            "ply\nformat ascii 1.0\nelement vertex {}\nproperty {ty} x\nproperty {ty} y\nproperty {ty} z\nend_header\n",
            rows.len()
        );
        for r in rows {
            s.push_str(r);
            s.push('\n');
        }
        s
    };
    let identical = vec!["0.5 0.5 0.5"; 100];
    let clouds = [
        ("one-point", ply("float", &["1 2 3"]), None),
        ("identical", ply("float", &identical), None),
        (
            "far-1e30",
            ply("float", &["1e30 0 0", "-1e30 0 0", "0 1e30 -1e30"]),
            Some("point 0 at (1e30, 0e0, 0e0) is beyond ±1e18"),
        ),
        (
            "beyond-f32-float",
            ply("float", &["1e39 0 0", "0 0 0", "1 1 1"]),
            Some("vertex 0 has a non-finite coordinate"),
        ),
        (
            "beyond-f32-double",
            ply("double", &["1e300 0 0", "0 0 0", "1 1 1"]),
            Some("vertex 0 has a non-finite coordinate"),
        ),
        (
            "one-far-outlier",
            ply(
                "float",
                &["0 0 0", "0.01 0 0", "0 0.01 0", "1e30 1e30 1e30"],
            ),
            Some("point 3 at (1e30, 1e30, 1e30) is beyond ±1e18"),
        ),
        (
            "just-inside",
            ply("float", &["1e17 0 0", "-1e17 0 0", "0 1e17 0"]),
            None,
        ),
    ];
    for (name, text, expected) in clouds {
        let input = dir.join(format!("{name}.ply"));
        std::fs::write(&input, text).unwrap();
        for method in ["pinhole", "rdb", "accum"] {
            let out = dir.join(format!("{name}-{method}.png"));
            let (i, o) = (input.display().to_string(), out.display().to_string());
            let mut args = vec![
                "render", &i, "-o", &o, "--width", "16", "--height", "12", "--method", method,
                "--device", "llvmpipe",
            ];
            if method == "accum" {
                args.extend(["--samples", "4"]);
            }
            let run = pointlens(&args);
            let err = String::from_utf8_lossy(&run.stderr);
            assert!(!err.contains("panicked"), "{name} {method}: {err}");
            match expected {
                None => {
                    assert!(run.status.success(), "{name} {method}: {err}");
                    let image = pointlens::image_io::read_image(&out).unwrap();
                    assert_eq!((image.width, image.height), (16, 12), "{name} {method}");
                    assert!(err.is_empty(), "{name} {method}: {err}");
                }
                Some(phrase) => {
                    assert!(!run.status.success(), "{name} {method} rendered");
                    assert_eq!(err.trim_end().lines().count(), 1, "{name} {method}: {err}");
                    assert!(err.contains(phrase), "{name} {method}: {err}");
                    assert!(!out.exists(), "{name} {method}: a file despite the error");
                }
            }
        }
    }
}

#[test]
fn a_closed_stdout_is_not_a_crash() {
    // `pointlens compare a b | head -1` and the like: the reader goes away
    // before pointlens writes. Its output is dropped, the command succeeds.
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let bunny_png = root().join("docs/bunny.png").display().to_string();
    let ply = root().join("data/bunny_colored.ply").display().to_string();
    for args in [
        vec!["compare", &bunny_png, &bunny_png],
        vec!["info", &ply],
        vec!["--list-devices"],
    ] {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_pointlens"))
            .args(&args)
            .stdout(writer.try_clone().unwrap())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}
