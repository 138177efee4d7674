//! Conversions from Python objects to plain Rust data, with the checks every entry point
//! shares: real numeric dtypes only (TypeError otherwise), shapes checked before any copy
//! (ValueError naming the argument), and every buffer sized by the input allocated fallibly
//! (MemoryError instead of an abort) after a check against the machine's memory.
//!
//! The data are always copied out of numpy, so the GIL can be released while Rust works on
//! them: another Python thread may change the array meanwhile without harm.

use numpy::{PyArrayDyn, PyArrayMethods};
use pyo3::exceptions::{PyMemoryError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// An empty vector with room for `n` values, or MemoryError naming `what`.
pub(crate) fn try_vec<T>(n: usize, what: &str) -> PyResult<Vec<T>> {
    let mut v = Vec::new();
    v.try_reserve_exact(n).map_err(|_| {
        PyMemoryError::new_err(format!(
            "{what}: cannot allocate {n} values of {} bytes",
            core::mem::size_of::<T>()
        ))
    })?;
    Ok(v)
}

/// Total physical memory, bytes (Linux: `/proc/meminfo`; `None` elsewhere).
fn total_memory_bytes() -> Option<u128> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kb: u128 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// MemoryError when a computation needs more than the machine has (`bytes` is an estimate;
/// the allocations themselves are fallible too, this catches what overcommit would let
/// through and then kill the process for).
pub(crate) fn check_memory(bytes: u128, what: &str) -> PyResult<()> {
    let too_big = bytes > isize::MAX as u128 || total_memory_bytes().is_some_and(|t| bytes > t);
    if too_big {
        let gb = bytes as f64 / 1e9;
        return Err(PyMemoryError::new_err(format!(
            "{what} needs about {gb:.3e} GB, more than this machine's memory"
        )));
    }
    Ok(())
}

/// `numpy.asarray(obj)` (no copy for an array) with a real numeric dtype (`f`, `i`, `u`);
/// TypeError naming the argument otherwise.
fn real_array<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<Bound<'py, PyAny>> {
    let np = obj.py().import("numpy")?;
    let arr = np.call_method1("asarray", (obj,)).map_err(|e| {
        PyTypeError::new_err(format!("{name}: not convertible to a numeric array: {e}"))
    })?;
    let dtype = arr.getattr("dtype")?;
    let kind: String = dtype.getattr("kind")?.extract()?;
    if !matches!(kind.as_str(), "f" | "i" | "u") {
        return Err(PyTypeError::new_err(format!(
            "{name}: expected a real numeric array, got dtype {}",
            dtype.str()?
        )));
    }
    Ok(arr)
}

fn shape_of(arr: &Bound<'_, PyAny>) -> PyResult<Vec<usize>> {
    arr.getattr("shape")?.extract()
}

/// The elements of a real array of a checked shape, row-major, as f64, copied into a
/// fallibly allocated vector. Native f64 arrays (any strides, read-only, broadcast) are read
/// in place; other dtypes go through `astype(float64)`.
fn copy_f64(arr: &Bound<'_, PyAny>, n: usize, name: &str) -> PyResult<Vec<f64>> {
    let mut out = try_vec::<f64>(n, name)?;
    let cast = match arr.cast::<PyArrayDyn<f64>>() {
        Ok(a) => a.clone(),
        Err(_) => {
            let np = arr.py().import("numpy")?;
            let kw = PyDict::new(arr.py());
            kw.set_item("dtype", np.getattr("float64")?)?;
            np.call_method("ascontiguousarray", (arr,), Some(&kw))?
                .cast_into::<PyArrayDyn<f64>>()?
        }
    };
    let ro = cast
        .try_readonly()
        .map_err(|e| PyValueError::new_err(format!("{name}: cannot read the array: {e}")))?;
    out.extend(ro.as_array().iter().copied());
    Ok(out)
}

/// An `(N, 2)` real array flattened row-major; ValueError naming the argument for another
/// shape, MemoryError when `N` is absurd.
pub(crate) fn rows2(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<f64>> {
    let arr = real_array(obj, name)?;
    let shape = shape_of(&arr)?;
    if shape.len() != 2 || shape[1] != 2 {
        return Err(PyValueError::new_err(format!(
            "{name}: expected shape (N, 2), got {shape:?}"
        )));
    }
    let n = shape[0].checked_mul(2).ok_or_else(|| {
        PyMemoryError::new_err(format!("{name}: {} rows cannot be held", shape[0]))
    })?;
    check_memory(n as u128 * 8, name)?;
    copy_f64(&arr, n, name)
}

/// A 1-D real array of length `n` (or any length if `None`).
pub(crate) fn vector(obj: &Bound<'_, PyAny>, name: &str, n: Option<usize>) -> PyResult<Vec<f64>> {
    let arr = real_array(obj, name)?;
    let shape = shape_of(&arr)?;
    match (shape.as_slice(), n) {
        ([len], Some(want)) if *len == want => {}
        ([_], None) => {}
        _ => {
            let want = n.map_or("(N,)".to_string(), |n| format!("({n},)"));
            return Err(PyValueError::new_err(format!(
                "{name}: expected shape {want}, got {shape:?}"
            )));
        }
    }
    check_memory(shape[0] as u128 * 8, name)?;
    copy_f64(&arr, shape[0], name)
}

/// A length-2 vector (shape `(2,)`).
pub(crate) fn pair(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; 2]> {
    let v = vector(obj, name, Some(2))?;
    Ok([v[0], v[1]])
}

/// A length-4 vector (shape `(4,)`).
pub(crate) fn vec4(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; 4]> {
    let v = vector(obj, name, Some(4))?;
    Ok([v[0], v[1], v[2], v[3]])
}

/// A config matrix given as an `(n, n)` array or a length-`n` diagonal.
pub(crate) fn square<const N: usize>(
    obj: &Bound<'_, PyAny>,
    name: &str,
) -> PyResult<[[f64; N]; N]> {
    let arr = real_array(obj, name)?;
    let shape = shape_of(&arr)?;
    let diagonal = match shape.as_slice() {
        [n] if *n == N => true,
        [n, m] if *n == N && *m == N => false,
        _ => {
            return Err(PyValueError::new_err(format!(
                "{name}: expected a ({N}, {N}) matrix or a length-{N} diagonal, got shape {shape:?}"
            )));
        }
    };
    let v = copy_f64(&arr, if diagonal { N } else { N * N }, name)?;
    Ok(core::array::from_fn(|r| {
        core::array::from_fn(|c| {
            if diagonal {
                if r == c { v[r] } else { 0.0 }
            } else {
                v[r * N + c]
            }
        })
    }))
}

/// `os.fspath(obj)` as a UTF-8 string; TypeError for anything else (bytes paths included).
pub(crate) fn path_string(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<String> {
    obj.py()
        .import("os")?
        .call_method1("fspath", (obj,))
        .and_then(|p| p.extract::<String>())
        .map_err(|_| PyTypeError::new_err(format!("{name}: expected a str or os.PathLike path")))
}
