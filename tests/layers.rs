//! The layering rules of docs/ARCHITECTURE.md ("Dependencies between
//! modules"), read from the sources: the splat hierarchy imports nothing
//! of the renderer or the loaders, the loaders nothing of the hierarchy,
//! `options` no code module, no pass the modules that build its input,
//! the CPU references nothing of the renderer, and `main.rs` stays a thin
//! binary.

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
        let close = format!("{indent}}}");
        let end = (i + 1..lines.len())
            .find(|&j| lines[j] == close)
            .unwrap_or_else(|| panic!("{}:{}: no end of fn {name}", file.display(), i + 1));
        found.push((name, i + 1, end - i + 1));
    }
    found
}

#[test]
fn no_function_of_the_binary_is_over_80_lines() {
    let main = src().join("main.rs");
    let all = functions(&main);
    assert!(
        all.iter().any(|(name, ..)| name == "main"),
        "the reader found no fn main"
    );
    let long: Vec<String> = all
        .iter()
        .filter(|(_, _, n)| *n > 80)
        .map(|(name, at, n)| format!("main.rs:{at}: fn {name}: {n} lines"))
        .collect();
    assert!(long.is_empty(), "{}", long.join("\n"));
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
             pub fn short() {{\n    crate::vk::f();\n}}\nuse crate::{{\n    cloud::X,\n    input,\n}};\n"
        ),
    )
    .unwrap();
    let named: Vec<String> = modules_named(&file).into_iter().map(|m| m.1).collect();
    assert_eq!(named, ["render", "vk", "cloud", "input"]);
    let fns = functions(&file);
    assert_eq!(fns[0], ("long".to_string(), 2, 81));
    assert_eq!(fns[1], ("short".to_string(), 83, 3));
    std::fs::remove_dir_all(&dir).unwrap();
}
