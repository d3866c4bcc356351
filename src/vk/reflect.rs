//! A minimal SPIR-V reader for one question: what layout does a shader
//! module give its push-constant block?
//!
//! The passes feed push constants from `#[repr(C)]` Rust structs whose
//! layout must agree, member by member (name, byte offset, byte size), with
//! the GLSL `layout(push_constant, std430) uniform` block the shader was
//! compiled from. [`push_constant_block`] reads that block back out of the
//! compiled module so that a test or a runtime check can compare the two
//! instead of trusting comments.
//!
//! It depends on nothing beyond `std` and reads only what it needs
//! (SPIR-V 1.6 specification, §2.3 "Physical Layout of a SPIR-V Module and
//! Instruction" for the word stream, §3 "Binary Form" for the enumerants
//! and opcodes):
//!
//! - the header: magic `0x07230203` in little-endian words (the form
//!   shaderc's `as_binary_u8` writes), then four more words it skips;
//! - every instruction's first word, `word count << 16 | opcode`, to walk
//!   the stream;
//! - `OpMemberName` (6) for member names, `OpDecorate` (71) with
//!   `ArrayStride` (6), and `OpMemberDecorate` (72) with `Offset` (35),
//!   `MatrixStride` (7) and `RowMajor` (4);
//! - the types `OpTypeBool` (20), `OpTypeInt` (21), `OpTypeFloat` (22),
//!   `OpTypeVector` (23), `OpTypeMatrix` (24), `OpTypeArray` (28),
//!   `OpTypeRuntimeArray` (29, reported as unsizable), `OpTypeStruct` (30)
//!   and `OpTypePointer` (32), plus `OpConstant` (43) for array lengths;
//! - `OpVariable` (59) with storage class `PushConstant` (9).
//!
//! Literal strings are nul-terminated UTF-8 packed four bytes to a word,
//! first byte in the lowest-order bits (§2.2.1).
//!
//! Names are debug information. shaderc at `OptimizationLevel::Performance`
//! (or `Size`) runs spirv-opt's strip-debug pass unless the compile options
//! ask for debug info (`set_generate_debug_info`), and that pass removes
//! every `OpName` and `OpMemberName`: such a module reflects with empty
//! names and only offsets and sizes can be compared. The optimiser keeps
//! unused block members and their `Offset` decorations.
//!
//! Sizes: a nested struct measures to the end of its last member, without
//! the tail padding std430 rounds it up with; an array with no
//! `ArrayStride` counts its elements tightly packed; a `PhysicalStorageBuffer`
//! pointer (a buffer device address) is 8 bytes.

use std::collections::{HashMap, HashSet};

/// One member of a push-constant block as the SPIR-V declares it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BlockMember {
    /// The GLSL member name (OpMemberName); empty when the module carries no names.
    pub name: String,
    /// Byte offset (the Offset member decoration).
    pub offset: u32,
    /// Size in bytes of the member's type (scalars, vectors, matrices with MatrixStride, arrays with ArrayStride × length, nested structs by their last member's offset + size).
    pub size: u32,
}

const MAGIC: u32 = 0x0723_0203;
const HEADER_WORDS: usize = 5;

const OP_MEMBER_NAME: u32 = 6;
const OP_TYPE_BOOL: u32 = 20;
const OP_TYPE_INT: u32 = 21;
const OP_TYPE_FLOAT: u32 = 22;
const OP_TYPE_VECTOR: u32 = 23;
const OP_TYPE_MATRIX: u32 = 24;
const OP_TYPE_ARRAY: u32 = 28;
const OP_TYPE_RUNTIME_ARRAY: u32 = 29;
const OP_TYPE_STRUCT: u32 = 30;
const OP_TYPE_POINTER: u32 = 32;
const OP_CONSTANT: u32 = 43;
const OP_VARIABLE: u32 = 59;
const OP_DECORATE: u32 = 71;
const OP_MEMBER_DECORATE: u32 = 72;

const DECORATION_ROW_MAJOR: u32 = 4;
const DECORATION_ARRAY_STRIDE: u32 = 6;
const DECORATION_MATRIX_STRIDE: u32 = 7;
const DECORATION_OFFSET: u32 = 35;

const STORAGE_PUSH_CONSTANT: u32 = 9;
const STORAGE_PHYSICAL_STORAGE_BUFFER: u32 = 5349;

/// Nesting deeper than this is taken for a malformed (cyclic) module.
const MAX_TYPE_DEPTH: u32 = 64;

/// The types this reader can size, by result id.
#[derive(Debug, Clone)]
enum Type {
    /// Bool, int or float: its size in bytes.
    Scalar(u32),
    Vector {
        component: u32,
        count: u32,
    },
    Matrix {
        column: u32,
        columns: u32,
    },
    Array {
        element: u32,
        length_id: u32,
    },
    RuntimeArray,
    Struct(Vec<u32>),
    Pointer {
        storage: u32,
        pointee: u32,
    },
}

/// Everything gathered in one pass over the module.
#[derive(Default)]
struct Module {
    types: HashMap<u32, Type>,
    /// `OpConstant` result id → its value, up to 64 bits (array lengths).
    constants: HashMap<u32, u64>,
    member_names: HashMap<(u32, u32), String>,
    member_offsets: HashMap<(u32, u32), u32>,
    matrix_strides: HashMap<(u32, u32), u32>,
    row_major: HashSet<(u32, u32)>,
    array_strides: HashMap<u32, u32>,
    /// Result types of the push-constant `OpVariable`s, in module order.
    push_variable_types: Vec<u32>,
}

/// The members of the module's push-constant block, in declaration order; an empty Vec when the module declares no push-constant variable. Errors (as a one-line String) for data that is not SPIR-V (bad magic, truncated instruction, word count 0), for more than one push-constant variable with different types, or for a member type it cannot size.
pub fn push_constant_block(spirv: &[u8]) -> Result<Vec<BlockMember>, String> {
    let words = to_words(spirv)?;
    let module = parse(&words)?;

    let mut blocks: Vec<u32> = Vec::new();
    for &pointer in &module.push_variable_types {
        let pointee = match module.types.get(&pointer) {
            Some(Type::Pointer { pointee, .. }) => *pointee,
            _ => {
                return Err(format!(
                    "SPIR-V: push-constant variable's type %{pointer} is not an OpTypePointer"
                ))
            }
        };
        if !blocks.contains(&pointee) {
            blocks.push(pointee);
        }
    }
    let block = match blocks.as_slice() {
        [] => return Ok(Vec::new()),
        [block] => *block,
        _ => {
            return Err(format!(
                "SPIR-V: {} push-constant variables with different block types",
                blocks.len()
            ))
        }
    };
    let Some(Type::Struct(members)) = module.types.get(&block) else {
        return Err(format!(
            "SPIR-V: push-constant block type %{block} is not an OpTypeStruct"
        ));
    };

    members
        .iter()
        .enumerate()
        .map(|(index, &ty)| {
            let index = index as u32;
            let offset = module.offset(block, index)?;
            let size = module.size_of(ty, (block, index), 0)?;
            let name = module
                .member_names
                .get(&(block, index))
                .cloned()
                .unwrap_or_default();
            Ok(BlockMember { name, offset, size })
        })
        .collect()
}

/// Little-endian bytes to words, with the magic number checked.
fn to_words(spirv: &[u8]) -> Result<Vec<u32>, String> {
    if !spirv.len().is_multiple_of(4) {
        return Err(format!(
            "SPIR-V: length {} bytes is not a multiple of 4",
            spirv.len()
        ));
    }
    let words: Vec<u32> = spirv
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    match words.first() {
        None => return Err("SPIR-V: empty module".to_string()),
        Some(&MAGIC) => {}
        Some(&magic) if magic == MAGIC.swap_bytes() => {
            return Err(
                "SPIR-V: big-endian module (byte-swapped magic), expected little-endian words"
                    .to_string(),
            )
        }
        Some(&magic) => {
            return Err(format!(
                "SPIR-V: bad magic number {magic:#010x}, expected {MAGIC:#010x}"
            ))
        }
    }
    if words.len() < HEADER_WORDS {
        return Err(format!(
            "SPIR-V: {} words is shorter than the {HEADER_WORDS}-word header",
            words.len()
        ));
    }
    Ok(words)
}

/// Walks the instruction stream after the header and records what
/// [`push_constant_block`] needs.
fn parse(words: &[u32]) -> Result<Module, String> {
    let mut module = Module::default();
    let mut at = HEADER_WORDS;
    while at < words.len() {
        let first = words[at];
        let count = (first >> 16) as usize;
        let opcode = first & 0xffff;
        if count == 0 {
            return Err(format!(
                "SPIR-V: instruction at word {at} (opcode {opcode}) has word count 0"
            ));
        }
        let Some(operands) = words.get(at + 1..at + count) else {
            return Err(format!(
                "SPIR-V: instruction at word {at} (opcode {opcode}) needs {count} words, {} remain",
                words.len() - at
            ));
        };
        module.record(opcode, operands, at)?;
        at += count;
    }
    Ok(module)
}

/// The first `N` operands of the instruction at word `at`, or an error
/// naming it when it has fewer.
fn operands<const N: usize>(ops: &[u32], opcode: u32, at: usize) -> Result<[u32; N], String> {
    ops.get(..N)
        .and_then(|s| <[u32; N]>::try_from(s).ok())
        .ok_or_else(|| {
            format!(
                "SPIR-V: instruction at word {at} (opcode {opcode}) has {} operands, needs {N}",
                ops.len()
            )
        })
}

/// A literal string: UTF-8 bytes packed low byte first, up to the first nul.
fn literal_string(words: &[u32]) -> String {
    let bytes: Vec<u8> = words
        .iter()
        .flat_map(|w| w.to_le_bytes())
        .take_while(|&b| b != 0)
        .collect();
    String::from_utf8_lossy(&bytes).into_owned()
}

impl Module {
    fn record(&mut self, opcode: u32, ops: &[u32], at: usize) -> Result<(), String> {
        match opcode {
            OP_MEMBER_NAME => {
                let [ty, member] = operands(ops, opcode, at)?;
                self.member_names
                    .insert((ty, member), literal_string(&ops[2..]));
            }
            OP_TYPE_BOOL => {
                let [id] = operands(ops, opcode, at)?;
                self.types.insert(id, Type::Scalar(4));
            }
            OP_TYPE_INT | OP_TYPE_FLOAT => {
                let [id, width] = operands(ops, opcode, at)?;
                self.types.insert(id, Type::Scalar(width / 8));
            }
            OP_TYPE_VECTOR => {
                let [id, component, count] = operands(ops, opcode, at)?;
                self.types.insert(id, Type::Vector { component, count });
            }
            OP_TYPE_MATRIX => {
                let [id, column, columns] = operands(ops, opcode, at)?;
                self.types.insert(id, Type::Matrix { column, columns });
            }
            OP_TYPE_ARRAY => {
                let [id, element, length_id] = operands(ops, opcode, at)?;
                self.types.insert(id, Type::Array { element, length_id });
            }
            OP_TYPE_RUNTIME_ARRAY => {
                let [id] = operands(ops, opcode, at)?;
                self.types.insert(id, Type::RuntimeArray);
            }
            OP_TYPE_STRUCT => {
                let [id] = operands(ops, opcode, at)?;
                self.types.insert(id, Type::Struct(ops[1..].to_vec()));
            }
            OP_TYPE_POINTER => {
                let [id, storage, pointee] = operands(ops, opcode, at)?;
                self.types.insert(id, Type::Pointer { storage, pointee });
            }
            OP_CONSTANT => {
                let [_ty, id, low] = operands(ops, opcode, at)?;
                // A 64-bit constant's high word follows the low one.
                let high = ops.get(3).copied().unwrap_or(0);
                self.constants
                    .insert(id, u64::from(high) << 32 | u64::from(low));
            }
            OP_VARIABLE => {
                let [ty, _id, storage] = operands(ops, opcode, at)?;
                if storage == STORAGE_PUSH_CONSTANT {
                    self.push_variable_types.push(ty);
                }
            }
            OP_DECORATE => {
                let [target, decoration] = operands(ops, opcode, at)?;
                if decoration == DECORATION_ARRAY_STRIDE {
                    let [_, _, stride] = operands(ops, opcode, at)?;
                    self.array_strides.insert(target, stride);
                }
            }
            OP_MEMBER_DECORATE => {
                let [ty, member, decoration] = operands(ops, opcode, at)?;
                let key = (ty, member);
                match decoration {
                    DECORATION_OFFSET => {
                        let [_, _, _, offset] = operands(ops, opcode, at)?;
                        self.member_offsets.insert(key, offset);
                    }
                    DECORATION_MATRIX_STRIDE => {
                        let [_, _, _, stride] = operands(ops, opcode, at)?;
                        self.matrix_strides.insert(key, stride);
                    }
                    DECORATION_ROW_MAJOR => {
                        self.row_major.insert(key);
                    }
                    _ => {}
                }
            }
            _ => {}
        }
        Ok(())
    }

    fn offset(&self, ty: u32, member: u32) -> Result<u32, String> {
        self.member_offsets
            .get(&(ty, member))
            .copied()
            .ok_or_else(|| {
                format!("SPIR-V: member {member} of struct %{ty} has no Offset decoration")
            })
    }

    /// Size in bytes of type `ty` where it appears as (part of) struct
    /// member `member`, whose decorations give matrix strides and majorness.
    fn size_of(&self, ty: u32, member: (u32, u32), depth: u32) -> Result<u32, String> {
        if depth > MAX_TYPE_DEPTH {
            return Err(format!(
                "SPIR-V: type %{ty} nests more than {MAX_TYPE_DEPTH} levels deep"
            ));
        }
        let overflow = || format!("SPIR-V: size of type %{ty} overflows 32 bits");
        let Some(t) = self.types.get(&ty) else {
            return Err(format!("SPIR-V: type %{ty} is undeclared or not sizable"));
        };
        match t {
            Type::Scalar(size) => Ok(*size),
            Type::Vector { component, count } => self
                .size_of(*component, member, depth + 1)?
                .checked_mul(*count)
                .ok_or_else(overflow),
            Type::Matrix { column, columns } => {
                let Some(Type::Vector {
                    component,
                    count: rows,
                }) = self.types.get(column)
                else {
                    return Err(format!("SPIR-V: matrix %{ty} column type is not a vector"));
                };
                // Column-major matrices are stored as columns, row-major
                // ones as rows, each vector MatrixStride after the last.
                let (vectors, length) = if self.row_major.contains(&member) {
                    (*rows, *columns)
                } else {
                    (*columns, *rows)
                };
                let stride = match self.matrix_strides.get(&member) {
                    Some(&stride) => stride,
                    None => self
                        .size_of(*component, member, depth + 1)?
                        .checked_mul(length)
                        .ok_or_else(overflow)?,
                };
                stride.checked_mul(vectors).ok_or_else(overflow)
            }
            Type::Array { element, length_id } => {
                let Some(&length) = self.constants.get(length_id) else {
                    return Err(format!(
                        "SPIR-V: array %{ty} length %{length_id} is not an OpConstant"
                    ));
                };
                let length = u32::try_from(length).map_err(|_| overflow())?;
                let stride = match self.array_strides.get(&ty) {
                    Some(&stride) => stride,
                    None => self.size_of(*element, member, depth + 1)?,
                };
                stride.checked_mul(length).ok_or_else(overflow)
            }
            Type::RuntimeArray => Err(format!("SPIR-V: runtime array %{ty} has no size")),
            Type::Struct(members) => {
                let mut end = 0u32;
                for (index, &member_ty) in members.iter().enumerate() {
                    let index = index as u32;
                    let offset = self.offset(ty, index)?;
                    let size = self.size_of(member_ty, (ty, index), depth + 1)?;
                    end = end.max(offset.checked_add(size).ok_or_else(overflow)?);
                }
                Ok(end)
            }
            // Buffer device addresses are 64-bit.
            Type::Pointer { storage, .. } if *storage == STORAGE_PHYSICAL_STORAGE_BUFFER => Ok(8),
            Type::Pointer { .. } => Err(format!(
                "SPIR-V: pointer type %{ty} has no size outside PhysicalStorageBuffer"
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FAST_COC: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fast_coc.comp.spv"));
    const SPLAT_VERT: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/splat_raster.vert.spv"));
    const SPLAT_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/splat_raster.frag.spv"));

    fn member(name: &str, offset: u32, size: u32) -> BlockMember {
        BlockMember {
            name: name.to_string(),
            offset,
            size,
        }
    }

    /// One instruction: the word count and opcode word, then the operands.
    fn inst(opcode: u32, operands: &[u32]) -> Vec<u32> {
        let count = operands.len() as u32 + 1;
        let mut words = vec![count << 16 | opcode];
        words.extend_from_slice(operands);
        words
    }

    /// A literal string as SPIR-V words, nul-terminated and zero-padded.
    fn string(s: &str) -> Vec<u32> {
        let mut bytes = s.as_bytes().to_vec();
        bytes.resize(s.len() / 4 * 4 + 4, 0);
        bytes
            .chunks_exact(4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect()
    }

    /// A SPIR-V 1.6 header with id bound `bound`, then the instructions.
    fn module(bound: u32, instructions: &[Vec<u32>]) -> Vec<u8> {
        let mut words = vec![MAGIC, 0x0001_0600, 0, bound, 0];
        for i in instructions {
            words.extend_from_slice(i);
        }
        words.iter().flat_map(|w| w.to_le_bytes()).collect()
    }

    fn concat(parts: &[&[u32]]) -> Vec<u32> {
        parts.concat()
    }

    /// Checks a reflected block against `(name, offset, size)` triples:
    /// offsets and sizes always, names only when the module carries any.
    /// build.rs compiles at `OptimizationLevel::Performance` without
    /// `set_generate_debug_info`, and shaderc then runs spirv-opt's
    /// strip-debug pass, which removes every OpName and OpMemberName: the
    /// project's modules reflect with all names empty.
    fn assert_block(actual: &[BlockMember], expected: &[(&str, u32, u32)]) {
        let named = actual.iter().any(|m| !m.name.is_empty());
        let expected: Vec<BlockMember> = expected
            .iter()
            .map(|&(name, offset, size)| member(if named { name } else { "" }, offset, size))
            .collect();
        assert_eq!(actual, expected, "names compared: {named}");
    }

    #[test]
    fn fast_coc_block() {
        // glsl/fast_coc.comp, std430.
        assert_block(
            &push_constant_block(FAST_COC).unwrap(),
            &[
                ("extent", 0, 8),
                ("f_px", 8, 4),
                ("aperture_radius", 12, 4),
                ("focus_distance", 16, 4),
                ("area_weights", 20, 4),
                ("shaped", 24, 4),
                ("tap_count", 28, 4),
                ("reach_max", 32, 4),
                ("background_only", 36, 4),
            ],
        );
    }

    #[test]
    fn splat_raster_block() {
        // glsl/splat_raster.glsl, std430: four vec4, four vec2, eight
        // floats. `pad` is never read, and the optimiser keeps it.
        let members = push_constant_block(SPLAT_VERT).unwrap();
        assert_block(
            &members,
            &[
                ("eye", 0, 16),
                ("right", 16, 16),
                ("up", 32, 16),
                ("forward", 48, 16),
                ("center", 64, 8),
                ("extent", 72, 8),
                ("jitter", 80, 8),
                ("lens_u", 88, 8),
                ("f_px", 96, 4),
                ("near", 100, 4),
                ("far", 104, 4),
                ("splat_px", 108, 4),
                ("aperture_radius", 112, 4),
                ("focus_distance", 116, 4),
                ("max_point_size", 120, 4),
                ("min_point_size", 124, 4),
            ],
        );
        let last = members.last().unwrap();
        assert_eq!(last.offset + last.size, 128);
    }

    #[test]
    fn no_push_constants_is_empty() {
        assert_eq!(push_constant_block(SPLAT_FRAG).unwrap(), vec![]);
        // A valid module with no entry point and no variables:
        // OpCapability Shader, OpCapability Linkage, OpMemoryModel.
        let bare = module(1, &[inst(17, &[1]), inst(17, &[5]), inst(14, &[0, 1])]);
        assert_eq!(push_constant_block(&bare).unwrap(), vec![]);
        // Header only.
        assert_eq!(push_constant_block(&module(1, &[])).unwrap(), vec![]);
    }

    /// A compute module (valid for `spirv-val --target-env vulkan1.3`) whose
    /// push block has a matrix with MatrixStride, an array with ArrayStride,
    /// a nested struct, a scalar and a row-major matrix, no names unless
    /// `named`. `variables` push-constant variables are declared,
    /// the second with its own pointer type to a second, identical struct
    /// when `distinct`.
    fn layout_module(named: bool, variables: u32, distinct: bool) -> Vec<u8> {
        // Ids.
        let (void, func, float, v3, v4, mat3, uint, c3, arr, inner, s, ptr, pc, main) =
            (1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14);
        let (s2, ptr2, label, pc2, mat2x3) = (15, 16, 17, 18, 19);
        let mut code = vec![
            inst(17, &[1]),                                    // OpCapability Shader
            inst(14, &[0, 1]),                                 // OpMemoryModel Logical GLSL450
            inst(15, &concat(&[&[5, main], &string("main")])), // OpEntryPoint GLCompute
            inst(16, &[main, 17, 1, 1, 1]),                    // OpExecutionMode LocalSize 1 1 1
        ];
        if named {
            code.push(inst(6, &concat(&[&[s, 0], &string("m")])));
            code.push(inst(6, &concat(&[&[s, 1], &string("a")])));
            code.push(inst(6, &concat(&[&[s, 2], &string("inner")])));
            code.push(inst(6, &concat(&[&[s, 3], &string("count")])));
            code.push(inst(6, &concat(&[&[s, 4], &string("rows")])));
        }
        for block in [s, s2] {
            code.extend([
                inst(71, &[block, 2]),          // Block
                inst(72, &[block, 0, 5]),       // ColMajor
                inst(72, &[block, 0, 35, 0]),   // Offset 0
                inst(72, &[block, 0, 7, 16]),   // MatrixStride 16
                inst(72, &[block, 1, 35, 48]),  // Offset 48
                inst(72, &[block, 2, 35, 96]),  // Offset 96
                inst(72, &[block, 3, 35, 128]), // Offset 128
                inst(72, &[block, 4, 4]),       // RowMajor
                inst(72, &[block, 4, 35, 144]), // Offset 144
                inst(72, &[block, 4, 7, 8]),    // MatrixStride 8
            ]);
        }
        code.extend([
            inst(71, &[arr, 6, 16]),       // ArrayStride 16
            inst(72, &[inner, 0, 35, 0]),  // Offset 0
            inst(72, &[inner, 1, 35, 16]), // Offset 16
            inst(19, &[void]),             // OpTypeVoid
            inst(33, &[func, void]),       // OpTypeFunction
            inst(22, &[float, 32]),        // OpTypeFloat 32
            inst(23, &[v3, float, 3]),     // vec3
            inst(23, &[v4, float, 4]),     // vec4
            inst(24, &[mat3, v3, 3]),      // mat3
            inst(24, &[mat2x3, v3, 2]),    // mat2x3
            inst(21, &[uint, 32, 0]),      // uint
            inst(43, &[uint, c3, 3]),      // OpConstant 3
            inst(28, &[arr, float, c3]),   // float[3]
            inst(30, &[inner, v4, float]), // struct { vec4; float; }
            inst(30, &[s, mat3, arr, inner, uint, mat2x3]),
            inst(30, &[s2, mat3, arr, inner, uint, mat2x3]),
            inst(32, &[ptr, 9, s]), // OpTypePointer PushConstant
            inst(32, &[ptr2, 9, s2]),
        ]);
        for i in 0..variables {
            let (p, v) = if distinct && i == 1 {
                (ptr2, pc2)
            } else {
                (ptr, pc + 100 * i)
            };
            code.push(inst(59, &[p, v, 9])); // OpVariable PushConstant
        }
        code.extend([
            inst(54, &[void, main, 0, func]), // OpFunction
            inst(248, &[label]),              // OpLabel
            inst(253, &[]),                   // OpReturn
            inst(56, &[]),                    // OpFunctionEnd
        ]);
        module(1000, &code)
    }

    #[test]
    fn matrices_arrays_and_nested_structs() {
        let expected = |names: [&str; 5]| {
            vec![
                // mat3: MatrixStride 16 × 3 columns, not 3 × vec3 = 36.
                member(names[0], 0, 48),
                // float[3]: ArrayStride 16 × 3, not 3 × 4.
                member(names[1], 48, 48),
                // struct { vec4 at 0; float at 16 }: the end of its last
                // member, without the tail padding std430 adds (to 32).
                member(names[2], 96, 20),
                member(names[3], 128, 4),
                // row_major mat2x3: 3 rows, MatrixStride 8 apart.
                member(names[4], 144, 24),
            ]
        };
        assert_eq!(
            push_constant_block(&layout_module(true, 1, false)).unwrap(),
            expected(["m", "a", "inner", "count", "rows"])
        );
        assert_eq!(
            push_constant_block(&layout_module(false, 1, false)).unwrap(),
            expected(["", "", "", "", ""])
        );
    }

    #[test]
    fn several_variables() {
        // Two variables of the same block type: its members, once.
        assert_eq!(
            push_constant_block(&layout_module(true, 2, false))
                .unwrap()
                .len(),
            5
        );
        // Two variables of different block types.
        let err = push_constant_block(&layout_module(true, 2, true)).unwrap_err();
        assert!(err.contains("different"), "{err}");
    }

    #[test]
    fn garbage_is_an_error() {
        let valid = module(1, &[inst(17, &[1])]);
        assert!(push_constant_block(&valid).is_ok());

        // Empty, and shorter than the header.
        assert!(push_constant_block(&[]).is_err());
        assert!(push_constant_block(&valid[..8]).is_err());
        // Length not a multiple of 4.
        assert!(push_constant_block(&valid[..valid.len() - 1]).is_err());
        assert!(push_constant_block(&FAST_COC[..FAST_COC.len() - 2]).is_err());
        // Wrong magic, and big-endian magic.
        let mut bad = valid.clone();
        bad[0] ^= 0xff;
        assert!(push_constant_block(&bad).unwrap_err().contains("magic"));
        let mut swapped = valid.clone();
        swapped[..4].copy_from_slice(&MAGIC.to_be_bytes());
        assert!(push_constant_block(&swapped)
            .unwrap_err()
            .contains("big-endian"));
        // A word count that runs past the end.
        let truncated = module(1, &[vec![3 << 16 | 17, 1]]);
        assert!(push_constant_block(&truncated)
            .unwrap_err()
            .contains("needs 3 words"));
        // Word count 0.
        let zero = module(1, &[vec![17]]);
        assert!(push_constant_block(&zero)
            .unwrap_err()
            .contains("word count 0"));
        // Too few operands for an instruction it reads.
        let short = module(1, &[inst(59, &[1, 2])]);
        assert!(push_constant_block(&short).is_err());
    }

    #[test]
    fn truncated_or_corrupted_modules_never_panic() {
        for spirv in [FAST_COC, SPLAT_VERT] {
            for len in (0..spirv.len()).step_by(4) {
                let _ = push_constant_block(&spirv[..len]);
            }
            let mut copy = spirv.to_vec();
            for at in (0..copy.len()).step_by(4) {
                let word = [copy[at], copy[at + 1], copy[at + 2], copy[at + 3]];
                for value in [0, 1, 0xffff, 0x0001_0000, 0xffff_ffff] {
                    copy[at..at + 4].copy_from_slice(&u32::to_le_bytes(value));
                    let _ = push_constant_block(&copy);
                }
                copy[at..at + 4].copy_from_slice(&word);
            }
        }
    }
}
