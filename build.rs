//! Compiles every `glsl/*.{vert,frag,comp}` to SPIR-V (Vulkan 1.3) with
//! shaderc, one shader per call, into `$OUT_DIR/<name>.spv`. A GLSL error
//! fails the build with `file:line: message`.

use std::path::{Path, PathBuf};

fn main() {
    let glsl = Path::new("glsl");
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    println!("cargo:rerun-if-changed=glsl");

    let mut shaders: Vec<PathBuf> = std::fs::read_dir(glsl)
        .expect("glsl/ directory")
        .map(|e| e.expect("readable glsl/ entry").path())
        .filter(|p| {
            matches!(
                p.extension().and_then(|e| e.to_str()),
                Some("vert" | "frag" | "comp")
            )
        })
        .collect();
    shaders.sort();

    let compiler = shaderc::Compiler::new().expect("shaderc compiler");
    let mut failed = false;
    for path in &shaders {
        if let Err(msg) = compile(&compiler, path, &out) {
            eprintln!("{msg}");
            failed = true;
        }
    }
    if failed {
        std::process::exit(1);
    }
}

fn compile(compiler: &shaderc::Compiler, path: &Path, out: &Path) -> Result<(), String> {
    println!("cargo:rerun-if-changed={}", path.display());
    let source = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let kind = match path.extension().and_then(|e| e.to_str()) {
        Some("vert") => shaderc::ShaderKind::Vertex,
        Some("frag") => shaderc::ShaderKind::Fragment,
        _ => shaderc::ShaderKind::Compute,
    };
    let mut options = shaderc::CompileOptions::new().map_err(|e| e.to_string())?;
    options.set_target_env(
        shaderc::TargetEnv::Vulkan,
        shaderc::EnvVersion::Vulkan1_3 as u32,
    );
    options.set_target_spirv(shaderc::SpirvVersion::V1_6);
    options.set_optimization_level(shaderc::OptimizationLevel::Performance);
    // Keeps OpName/OpMemberName (shaderc strips them otherwise), so that the
    // push-constant check (src/vk/pipeline.rs) compares member names, not
    // only offsets and sizes. The driver ignores debug instructions.
    options.set_generate_debug_info();
    options.set_warnings_as_errors();
    options.set_include_callback(|name, _ty, from, _depth| {
        let dir = Path::new(from).parent().unwrap_or(Path::new("glsl"));
        let inc = dir.join(name);
        println!("cargo:rerun-if-changed={}", inc.display());
        let content = std::fs::read_to_string(&inc)
            .map_err(|e| format!("{from}: cannot include {}: {e}", inc.display()))?;
        Ok(shaderc::ResolvedInclude {
            resolved_name: inc.display().to_string(),
            content,
        })
    });
    let name = path.display().to_string();
    let artifact = compiler
        .compile_into_spirv(&source, kind, &name, "main", Some(&options))
        .map_err(|e| format!("GLSL error:\n{e}"))?;
    let file = path
        .file_name()
        .expect("shader file name")
        .to_string_lossy();
    std::fs::write(out.join(format!("{file}.spv")), artifact.as_binary_u8())
        .map_err(|e| format!("{file}.spv: {e}"))
}
