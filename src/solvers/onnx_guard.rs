//! What keeps a hostile policy file from crashing or exhausting the process (docs/limits.md):
//!
//! * [`guarded`] runs a call into the ONNX runtime (`tract`) and turns a panic of the runtime
//!   (an allocation that fails, an index out of range, an integer division by zero) into an
//!   error, without the panic's message on stderr;
//! * [`check_declared`] refuses, before the runtime sees the graph, tensors whose declared
//!   size (initializers, constants, the shapes given to `ConstantOfShape`, `Expand`, `Tile`)
//!   exceeds [`MAX_TENSOR_ELEMENTS`], and constants (initializers, constant tensors, float
//!   attributes) holding NaN or an infinity: a NaN action floor, say, which tract's `Max`
//!   skips and onnxruntime's returns;
//! * [`check_typed`] refuses a graph, fitted to one observation, that computes a tensor of
//!   unknown size or beyond the limit, or multiplies by a constant zero (which the two
//!   runtimes evaluate differently: tract folds `x * 0` to 0, onnxruntime gives NaN for a NaN
//!   `x`).
use std::cell::{Cell, RefCell};
use std::panic::AssertUnwindSafe;
use std::sync::Once;

use tract_onnx::pb::{GraphProto, TensorProto};
use tract_onnx::prelude::*;
use tract_onnx::tract_core::ops::binary::TypedBinOp;

/// The most elements one tensor of a policy file may hold, declared or computed (16 M; a
/// trained policy's largest weight matrix holds well under a million).
pub const MAX_TENSOR_ELEMENTS: u64 = 1 << 24;

thread_local! {
    /// Whether this thread is inside [`guarded`] (its panics are errors, not messages).
    static QUIET: Cell<bool> = const { Cell::new(false) };
    /// The message of the last panic caught by [`guarded`] on this thread.
    static CAUGHT: RefCell<Option<String>> = const { RefCell::new(None) };
}

/// Installs (once) a panic hook that keeps quiet inside [`guarded`] and otherwise calls the
/// hook that was there before.
fn install_hook() {
    static HOOK: Once = Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if QUIET.with(Cell::get) {
                let msg = info
                    .payload()
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| info.payload().downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "no message".into());
                let at = info
                    .location()
                    .map(|l| format!(" at {}:{}", l.file(), l.line()))
                    .unwrap_or_default();
                CAUGHT.with(|c| *c.borrow_mut() = Some(format!("{msg}{at}")));
            } else {
                previous(info);
            }
        }));
    });
}

/// Runs `f`, a call into the ONNX runtime: its error, or a panic inside it, becomes an error
/// message (`the runtime crashed: …` with the panic's message).
pub fn guarded<T>(f: impl FnOnce() -> TractResult<T>) -> Result<T, String> {
    install_hook();
    let was = QUIET.with(|q| q.replace(true));
    let r = std::panic::catch_unwind(AssertUnwindSafe(f));
    QUIET.with(|q| q.set(was));
    match r {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(format!("{e:#}")),
        Err(_) => {
            let msg = CAUGHT
                .with(|c| c.borrow_mut().take())
                .unwrap_or_else(|| "no message".into());
            Err(format!("the ONNX runtime crashed ({msg})"))
        }
    }
}

/// The element count of `dims`, None when a dimension is negative or the product overflows.
fn elements(dims: &[i64]) -> Option<u64> {
    dims.iter().try_fold(1u64, |n, &d| {
        u64::try_from(d).ok().and_then(|d| n.checked_mul(d))
    })
}

/// The values of a small int64 tensor (initializer or constant), None otherwise.
fn int64_values(t: &TensorProto) -> Option<Vec<i64>> {
    const INT64: i32 = 7;
    if t.data_type != INT64 || elements(&t.dims)? > 64 {
        return None;
    }
    if !t.int64_data.is_empty() {
        return Some(t.int64_data.clone());
    }
    Some(
        t.raw_data
            .chunks_exact(8)
            .map(|c| i64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect(),
    )
}

fn too_large(what: String, dims: &[i64]) -> String {
    format!(
        "{what} declares a tensor of shape {dims:?}, beyond the limit of {MAX_TENSOR_ELEMENTS} \
         elements per tensor (docs/limits.md)"
    )
}

fn check_tensor(what: impl Fn() -> String, t: &TensorProto) -> Result<(), String> {
    match elements(&t.dims) {
        Some(n) if n <= MAX_TENSOR_ELEMENTS => {}
        _ => return Err(too_large(what(), &t.dims)),
    }
    match first_non_finite(t) {
        Some((i, v)) => Err(non_finite(&what(), i, v)),
        None => Ok(()),
    }
}

/// The index and value of the first NaN or infinity among the floats of `t` (f32, f64, f16,
/// bf16; as stored, in `raw_data` or the typed fields), None when all are finite.
fn first_non_finite(t: &TensorProto) -> Option<(usize, f64)> {
    const FLOAT: i32 = 1;
    const FLOAT16: i32 = 10;
    const DOUBLE: i32 = 11;
    const BFLOAT16: i32 = 16;
    let first = |it: &mut dyn Iterator<Item = f64>| it.enumerate().find(|(_, v)| !v.is_finite());
    let raw = |w: usize| t.raw_data.chunks_exact(w);
    match t.data_type {
        FLOAT if !t.float_data.is_empty() => first(&mut t.float_data.iter().map(|&v| v.into())),
        FLOAT => {
            first(&mut raw(4).map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")).into()))
        }
        DOUBLE if !t.double_data.is_empty() => first(&mut t.double_data.iter().copied()),
        DOUBLE => first(&mut raw(8).map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))),
        FLOAT16 | BFLOAT16 => {
            // 16 bits a value (in int32_data or raw_data): all exponent bits set is an
            // infinity (mantissa 0) or a NaN.
            let exponent: u16 = if t.data_type == FLOAT16 {
                0x7c00
            } else {
                0x7f80
            };
            let bits: Box<dyn Iterator<Item = u16>> = if t.int32_data.is_empty() {
                Box::new(raw(2).map(|c| u16::from_le_bytes(c.try_into().expect("2 bytes"))))
            } else {
                Box::new(t.int32_data.iter().map(|&v| v as u16))
            };
            let (i, b) = bits.enumerate().find(|(_, b)| b & exponent == exponent)?;
            let nan = b & !(exponent | 0x8000) != 0;
            let inf = if b & 0x8000 != 0 {
                f64::NEG_INFINITY
            } else {
                f64::INFINITY
            };
            Some((i, if nan { f64::NAN } else { inf }))
        }
        _ => None,
    }
}

fn non_finite(what: &str, i: usize, v: f64) -> String {
    format!(
        "{what} holds {v} at index {i}; a policy file's constants must be finite numbers (the \
         runtimes disagree on NaN: tract's Max and Min skip it, onnxruntime's return it)"
    )
}

/// Checks the declared sizes of `graph` and its subgraphs (see the module documentation).
pub fn check_declared(graph: &GraphProto) -> Result<(), String> {
    let mut constants: std::collections::HashMap<&str, Vec<i64>> = Default::default();
    for t in &graph.initializer {
        check_tensor(
            || format!("initializer {:?}", crate::files::short(&t.name)),
            t,
        )?;
        if let Some(v) = int64_values(t) {
            constants.insert(&t.name, v);
        }
    }
    for node in &graph.node {
        let name = || {
            format!(
                "node {:?} ({})",
                crate::files::short(&node.name),
                node.op_type
            )
        };
        for a in &node.attribute {
            let what = || format!("{} attribute {:?}", name(), crate::files::short(&a.name));
            if !a.f.is_finite() {
                return Err(non_finite(&what(), 0, a.f.into()));
            }
            if let Some((i, v)) = a.floats.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(non_finite(&what(), i, f64::from(*v)));
            }
            if let Some(t) = &a.t {
                check_tensor(name, t)?;
                if node.op_type == "Constant" {
                    if let (Some(out), Some(v)) = (node.output.first(), int64_values(t)) {
                        constants.insert(out, v);
                    }
                }
            }
            for t in &a.tensors {
                check_tensor(name, t)?;
            }
            for g in a.g.iter().chain(&a.graphs) {
                check_declared(g)?;
            }
        }
        // Ops whose output size is given by a constant input.
        let shape_input = match node.op_type.as_str() {
            "ConstantOfShape" => 0,
            "Expand" | "Tile" => 1,
            _ => continue,
        };
        let Some(v) = node
            .input
            .get(shape_input)
            .and_then(|i| constants.get(i.as_str()))
        else {
            continue;
        };
        match elements(v) {
            Some(n) if n <= MAX_TENSOR_ELEMENTS => {}
            _ => return Err(too_large(name(), v)),
        }
    }
    Ok(())
}

/// Checks a typed graph fitted to one observation (see the module documentation).
pub fn check_typed(model: &TypedModel) -> Result<(), String> {
    for node in model.nodes() {
        for (slot, out) in node.outputs.iter().enumerate() {
            let name = || {
                format!(
                    "node {:?} ({})",
                    crate::files::short(&node.name),
                    node.op.name()
                )
            };
            let Some(shape) = out.fact.shape.as_concrete() else {
                return Err(format!(
                    "{} computes output {slot} of shape {:?}, whose size depends on the \
                     observation's values; a policy file's tensors have sizes fixed by the \
                     observation size",
                    name(),
                    out.fact.shape
                ));
            };
            let n = shape.iter().try_fold(1u64, |n, &d| n.checked_mul(d as u64));
            if n.is_none_or(|n| n > MAX_TENSOR_ELEMENTS) {
                return Err(format!(
                    "{} computes a tensor of shape {shape:?}, beyond the limit of \
                     {MAX_TENSOR_ELEMENTS} elements per tensor (docs/limits.md)",
                    name()
                ));
            }
        }
        let Some(bin) = node.op_as::<TypedBinOp>() else {
            continue;
        };
        if bin.0.name() != "Mul" || !node.outputs[0].fact.datum_type.is_float() {
            continue;
        }
        let facts = model
            .node_input_facts(node.id)
            .map_err(|e| format!("{e:#}"))?;
        let zero = facts.iter().any(|f| {
            f.uniform
                .as_ref()
                .is_some_and(|u| u.cast_to_scalar::<f64>().is_ok_and(|v| v == 0.0))
        });
        if zero && facts.iter().any(|f| f.konst.is_none()) {
            return Err(format!(
                "node {:?} multiplies by a constant zero: runtimes disagree on its result \
                 (tract folds x × 0 to 0, onnxruntime gives NaN for x = NaN), so policy files \
                 may not do it",
                crate::files::short(&node.name)
            ));
        }
    }
    Ok(())
}
