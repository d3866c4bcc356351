//! The layering rules of docs/ARCHITECTURE.md ("Dependencies between
//! modules"), read from the sources: the splat hierarchy imports nothing
//! of the renderer or the loaders, the loaders nothing of the hierarchy,
//! `options` no code module, no pass the modules that build its input,
//! the CPU references nothing of the renderer, `main.rs` only parses, and
//! functions stay short enough to read.

use std::path::{Path, PathBuf};

fn src() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("src")
}

/// The Rust files of `dir` (not recursive), or `dir` itself if a file.
fn rust_files(path: &Path) -> Vec<PathBuf> {
    if path.is_file() {
        return vec![path.to_path_buf()];
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "rs"))
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no Rust file in {}", path.display());
    files
}

/// The crate modules a file names (`crate::x`, `crate::{x, y::z}`),
/// outside comments, with the line of each.
fn modules_named(file: &Path) -> Vec<(usize, String)> {
    let text = std::fs::read_to_string(file).unwrap();
    // The code without comments, and the line of each of its bytes.
    let mut code = String::new();
    let mut line_of = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let kept = line.split("//").next().unwrap_or("");
        code.push_str(kept);
        code.push('\n');
        line_of.extend(std::iter::repeat_n(i + 1, kept.len() + 1));
    }
    let ident = |s: &str| -> String {
        s.trim_start()
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect()
    };
    let mut named = Vec::new();
    for (at, _) in code.match_indices("crate::") {
        let rest = &code[at + "crate::".len()..];
        match rest.strip_prefix('{') {
            // A group: the first segment of each path in it.
            Some(group) => {
                let group = &group[..group.find('}').unwrap_or(group.len())];
                named.extend(group.split(',').map(|p| (line_of[at], ident(p))));
            }
            None => named.push((line_of[at], ident(rest))),
        }
    }
    named.retain(|(_, m)| !m.is_empty());
    named
}

/// Fails naming every line of `path`'s files that names a module of
/// `forbidden`.
fn assert_imports_none(path: &str, forbidden: &[&str]) {
    let mut found = Vec::new();
    for file in rust_files(&src().join(path)) {
        for (line, module) in modules_named(&file) {
            if forbidden.contains(&module.as_str()) {
                found.push(format!("{}:{line}: crate::{module}", file.display()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "{path} may not import {forbidden:?}:\n{}",
        found.join("\n")
    );
}

#[test]
fn the_splat_hierarchy_imports_nothing_of_the_renderer_or_the_loaders() {
    assert_imports_none(
        "tree",
        &["render", "passes", "gbuffer", "vk", "cloud", "input", "job"],
    );
}

#[test]
fn the_loaders_know_no_hierarchy_and_no_renderer() {
    let renderer = ["tree", "render", "passes", "gbuffer", "vk", "job", "bench"];
    assert_imports_none("input", &renderer);
    assert_imports_none("cloud.rs", &renderer);
    // `cloud` is the type alone: it loads nothing.
    assert_imports_none("cloud.rs", &["input"]);
}

#[test]
fn options_import_no_code_module() {
    for file in rust_files(&src().join("options.rs")) {
        for (line, module) in modules_named(&file) {
            assert_eq!(module, "error", "{}:{line}", file.display());
        }
    }
}

#[test]
fn no_pass_imports_the_modules_that_build_its_input() {
    // A method gets the G-buffer as a `DofInput` and declares its veil
    // rule in its own terms (`passes::VeilRule`).
    assert_imports_none("passes", &["veil", "gbuffer"]);
}

#[test]
fn the_cpu_references_know_no_renderer() {
    let renderer = ["render", "passes", "vk", "gbuffer", "job"];
    assert_imports_none("reference.rs", &renderer);
    assert_imports_none("fields.rs", &renderer);
    assert_imports_none("host_gbuffer.rs", &renderer);
}

/// Every function of `file`: (name, first line, number of lines), from
/// `fn` to the closing brace at its indentation (the layout rustfmt gives).
fn functions(file: &Path) -> Vec<(String, usize, usize)> {
    let text = std::fs::read_to_string(file).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let mut found = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let trimmed = line.trim_start();
        let indent = &line[..line.len() - trimmed.len()];
        let signature = trimmed
            .strip_prefix("pub ")
            .unwrap_or(trimmed)
            .strip_prefix("fn ");
        let Some(signature) = signature else {
            continue;
        };
        let name: String = signature
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        // A declaration without a body (a trait's) ends in `;` before
        // any `{`.
        let opens = (i..lines.len()).find(|&j| {
            let l = lines[j].split("//").next().unwrap_or("").trim_end();
            l.ends_with('{') || l.ends_with(';')
        });
        if opens.is_some_and(|j| {
            lines[j]
                .split("//")
                .next()
                .unwrap_or("")
                .trim_end()
                .ends_with(';')
        }) {
            continue;
        }
        let close = format!("{indent}}}");
        let end = (i + 1..lines.len())
            .find(|&j| lines[j] == close)
            .unwrap_or_else(|| panic!("{}:{}: no end of fn {name}", file.display(), i + 1));
        found.push((name, i + 1, end - i + 1));
    }
    found
}

/// Fails naming every function of the `.rs` files under `path` (recursive
/// where `path` is a folder) longer than `most` lines.
fn assert_no_function_over(path: &Path, most: usize) {
    let mut files = vec![path.to_path_buf()];
    let mut long = Vec::new();
    while let Some(file) = files.pop() {
        if file.is_dir() {
            files.extend(std::fs::read_dir(&file).unwrap().map(|e| e.unwrap().path()));
            continue;
        }
        if file.extension().is_none_or(|x| x != "rs") {
            continue;
        }
        for (name, at, n) in functions(&file) {
            if n > most {
                long.push(format!("{}:{at}: fn {name}: {n} lines", file.display()));
            }
        }
    }
    long.sort();
    assert!(long.is_empty(), "over {most} lines:\n{}", long.join("\n"));
}

#[test]
fn the_binary_only_parses() {
    let main = src().join("main.rs");
    assert!(
        functions(&main).iter().any(|(name, ..)| name == "main"),
        "the reader found no fn main"
    );
    assert_no_function_over(&main, 60);
    let lines = std::fs::read_to_string(&main).unwrap().lines().count();
    assert!(lines <= 700, "main.rs has {lines} lines (at most 700)");
    // It reads no file, sets up no renderer and drives no frame: the
    // library's modules that do are not named in it.
    let text = std::fs::read_to_string(&main).unwrap();
    let code: String = text
        .lines()
        .map(|l| l.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n");
    for module in [
        "render",
        "gaussian_render",
        "tree",
        "passes",
        "gbuffer",
        "cloud",
        "reference",
    ] {
        for spelled in [
            format!("pointlens::{module}::"),
            format!("pointlens::{{{module}"),
        ] {
            assert!(!code.contains(&spelled), "main.rs names {spelled}");
        }
    }
    for name in [
        "Context::new",
        "Renderer",
        "HostScene",
        "load_cloud",
        "load_gaussians",
        "CopcClouds",
        "watch_signals",
    ] {
        assert!(!code.contains(name), "main.rs names {name}");
    }
}

#[test]
fn no_function_outside_the_vulkan_set_up_is_over_120_lines() {
    for entry in std::fs::read_dir(src()).unwrap() {
        let path = entry.unwrap().path();
        if path.file_name().is_some_and(|n| n != "vk") {
            assert_no_function_over(&path, 120);
        }
    }
}

#[test]
fn the_readers_see_what_they_check() {
    // The readers above, on text made to break each rule.
    let dir = std::env::temp_dir().join(format!("pointlens-layers-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("x.rs");
    let long_body = "    let x = 1;\n".repeat(79);
    std::fs::write(
        &file,
        format!(
            "use crate::render::Scene; // crate::vk in a comment\nfn long() {{\n{long_body}}}\n\
             pub fn short() {{\n    crate::vk::f();\n}}\nuse crate::{{\n    cloud::X,\n    input,\n}};\n\
             trait T {{\n    fn declared(&self);\n}}\n"
        ),
    )
    .unwrap();
    let named: Vec<String> = modules_named(&file).into_iter().map(|m| m.1).collect();
    assert_eq!(named, ["render", "vk", "cloud", "input"]);
    let fns = functions(&file);
    assert_eq!(fns[0], ("long".to_string(), 2, 81));
    assert_eq!(fns[1], ("short".to_string(), 83, 3));
    // A declaration without a body is no function to measure.
    assert_eq!(fns.len(), 2, "{fns:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}
