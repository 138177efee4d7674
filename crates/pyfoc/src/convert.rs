//! Conversions from Python objects to plain Rust data, with the checks every entry point
//! shares: real dtypes only (TypeError otherwise), shapes checked before any copy (ValueError
//! naming the argument), and every buffer sized by the input allocated fallibly (MemoryError
//! instead of an abort), after one probe of the whole call's memory.
//!
//! Arrays come in through rust-numpy's [`PyArrayLikeDyn`] with [`AllowTypeChange`]: a float64
//! ndarray is read in place (any strides, read-only, broadcast), other real dtypes and nested
//! sequences are converted to float64 by numpy itself. The data are then copied out, so the
//! GIL can be released while Rust works on them: another Python thread may change the array
//! meanwhile without harm.

use numpy::{
    AllowTypeChange, PyArrayDescrMethods, PyArrayLikeDyn, PyReadonlyArrayDyn, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyMemoryError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyInt, PyList, PyString, PyTuple};

/// A real array, float64, borrowed read-only from Python (no copy for a float64 ndarray).
pub(crate) type RealArray<'py> = PyReadonlyArrayDyn<'py, f64>;

/// The slice of an array numpy has just allocated for `pyfoc` (always contiguous), or a
/// RuntimeError should it not be.
pub(crate) fn contiguous<S>(r: Result<S, numpy::AsSliceError>) -> PyResult<S> {
    r.map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(format!("internal array: {e}")))
}

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

/// MemoryError, before anything is allocated, when a call needs `bytes` in total and the
/// system refuses them in one request. The probe reserves address space and gives it back
/// without touching it: the operating system compares the request with what it can back
/// (Linux's default overcommit heuristic refuses a request larger than RAM + swap), so a
/// call whose buffers would each fit but together would not is refused as a whole, rather
/// than killed half-way by the OOM killer.
pub(crate) fn ensure_memory(bytes: u128, what: &str) -> PyResult<()> {
    let refused = || {
        PyMemoryError::new_err(format!(
            "{what} needs about {:.3e} GB, more than this machine can allocate",
            bytes as f64 / 1e9
        ))
    };
    let n = usize::try_from(bytes).map_err(|_| refused())?;
    Vec::<u8>::new().try_reserve_exact(n).map_err(|_| refused())
}

/// A real array-like as float64. Accepted: ndarrays of the dtypes numpy casts to float64
/// under `same_kind` rules (float, signed and unsigned int, bool as 0/1), and nested
/// sequences or scalars numpy converts to float64. TypeError naming the argument for None,
/// str and bytes, for ndarrays of complex (the cast would drop the imaginary part), object,
/// string, datetime, timedelta or structured dtype, and for what numpy cannot convert.
pub(crate) fn real_array<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<RealArray<'py>> {
    if let Ok(arr) = obj.cast::<PyUntypedArray>() {
        let dtype = arr.dtype();
        if !matches!(dtype.kind(), b'f' | b'i' | b'u' | b'b') {
            return Err(PyTypeError::new_err(format!(
                "{name}: expected a real numeric array, got dtype {}",
                dtype.str()?
            )));
        }
    } else if obj.is_none() || obj.is_instance_of::<PyString>() || obj.is_instance_of::<PyBytes>() {
        return Err(PyTypeError::new_err(format!(
            "{name}: expected a real numeric array, got {}",
            obj.get_type().name()?
        )));
    }
    let like: PyArrayLikeDyn<'py, f64, AllowTypeChange> = obj.extract().map_err(|e| {
        PyTypeError::new_err(format!(
            "{name}: not convertible to a real numeric array: {e}"
        ))
    })?;
    Ok(like.clone())
}

/// The elements of `arr`, row-major, copied into a fallibly allocated vector.
pub(crate) fn to_vec(arr: &RealArray<'_>, name: &str) -> PyResult<Vec<f64>> {
    let mut out = try_vec::<f64>(arr.len(), name)?;
    extend_with(&mut out, arr);
    Ok(out)
}

/// Appends the elements of `arr`, row-major, to `v` (which should have the room: the
/// callers reserve it fallibly first).
pub(crate) fn extend_with(v: &mut Vec<f64>, arr: &RealArray<'_>) {
    let a = arr.as_array();
    // ndarray's slice exists for the C (row-major) layout only; any other is read by index.
    match a.as_slice() {
        Some(s) => v.extend_from_slice(s),
        None => v.extend(a.iter().copied()),
    }
}

/// An `(N, 2)` real array (not copied); ValueError naming the argument for another shape.
pub(crate) fn rows2<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<RealArray<'py>> {
    let arr = real_array(obj, name)?;
    let shape = arr.shape();
    if shape.len() != 2 || shape[1] != 2 {
        return Err(PyValueError::new_err(format!(
            "{name}: expected shape (N, 2), got {}",
            shape_str(shape)
        )));
    }
    Ok(arr)
}

/// A 1-D real array of length `n` (or any length if `None`), not copied.
pub(crate) fn vector<'py>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    n: Option<usize>,
) -> PyResult<RealArray<'py>> {
    let arr = real_array(obj, name)?;
    match (arr.shape(), n) {
        ([len], Some(want)) if *len == want => Ok(arr),
        ([_], None) => Ok(arr),
        (shape, _) => {
            let want = n.map_or("(N,)".to_string(), |n| format!("({n},)"));
            Err(PyValueError::new_err(format!(
                "{name}: expected shape {want}, got {}",
                shape_str(shape)
            )))
        }
    }
}

/// The record arguments of a `run`: `u_ab` and `i_ab` as `(N, 2)` arrays of one length `N`,
/// and `u_prev` (shape `(2,)`) when given; errors name the argument.
#[allow(clippy::type_complexity)]
pub(crate) fn record_args<'py>(
    u_ab: &Bound<'py, PyAny>,
    i_ab: &Bound<'py, PyAny>,
    u_prev: Option<&Bound<'py, PyAny>>,
) -> PyResult<(RealArray<'py>, RealArray<'py>, usize, Option<[f64; 2]>)> {
    let u = rows2(u_ab, "u_ab")?;
    let i = rows2(i_ab, "i_ab")?;
    let n = u.shape()[0];
    if n != i.shape()[0] {
        return Err(PyValueError::new_err(format!(
            "u_ab and i_ab must have the same length, got {n} and {}",
            i.shape()[0]
        )));
    }
    let u_prev = u_prev.map(|p| fixed::<2>(p, "u_prev")).transpose()?;
    Ok((u, i, n, u_prev))
}

/// A fixed-length vector (shape `(N,)`).
pub(crate) fn fixed<const N: usize>(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; N]> {
    let arr = vector(obj, name, Some(N))?;
    let v = arr.as_array();
    Ok(core::array::from_fn(|k| v[k]))
}

/// A config matrix given as an `(n, n)` array or a length-`n` diagonal.
pub(crate) fn square<const N: usize>(
    obj: &Bound<'_, PyAny>,
    name: &str,
) -> PyResult<[[f64; N]; N]> {
    let arr = real_array(obj, name)?;
    let a = arr.as_array();
    match arr.shape() {
        [n] if *n == N => Ok(core::array::from_fn(|r| {
            core::array::from_fn(|c| if r == c { a[[r]] } else { 0.0 })
        })),
        [n, m] if *n == N && *m == N => Ok(core::array::from_fn(|r| {
            core::array::from_fn(|c| a[[r, c]])
        })),
        shape => Err(PyValueError::new_err(format!(
            "{name}: expected a ({N}, {N}) matrix or a length-{N} diagonal, got shape {}",
            shape_str(shape)
        ))),
    }
}

/// A shape as numpy prints it: `(10,)`, `(3, 2)`, `()`.
fn shape_str(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => {
            let dims: Vec<String> = shape.iter().map(ToString::to_string).collect();
            format!("({})", dims.join(", "))
        }
    }
}

/// ValueError naming `what` when dicts, lists and tuples in `obj` nest deeper than `max`
/// levels (a recursive container nests without end).
pub(crate) fn nesting_within(obj: &Bound<'_, PyAny>, max: usize, what: &str) -> PyResult<()> {
    fn depth_ok(obj: &Bound<'_, PyAny>, left: usize) -> PyResult<bool> {
        let children: Vec<Bound<'_, PyAny>> = if let Ok(d) = obj.cast::<PyDict>() {
            d.values().iter().collect()
        } else if let Ok(l) = obj.cast::<PyList>() {
            l.iter().collect()
        } else if let Ok(t) = obj.cast::<PyTuple>() {
            t.iter().collect()
        } else {
            return Ok(true);
        };
        if left == 0 {
            return Ok(false);
        }
        for c in &children {
            if !depth_ok(c, left - 1)? {
                return Ok(false);
            }
        }
        Ok(true)
    }
    if depth_ok(obj, max)? {
        Ok(())
    } else {
        Err(PyValueError::new_err(format!(
            "{what}: nested deeper than {max} levels (a recursive container?)"
        )))
    }
}

/// A filesystem path (`str` or `os.PathLike`, through `os.fspath`); TypeError for anything
/// else, bytes paths included.
pub(crate) fn path_of(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<std::path::PathBuf> {
    if obj.is_instance_of::<PyBytes>() {
        return Err(PyTypeError::new_err(format!(
            "{name}: expected a str or os.PathLike path, got bytes"
        )));
    }
    obj.extract()
        .map_err(|_| PyTypeError::new_err(format!("{name}: expected a str or os.PathLike path")))
}

/// A non-negative integer argument (a seed, a count): `ValueError` naming the argument when it
/// is negative or too large for `T`, `TypeError` naming it when it is not an integer (Python's
/// own conversion would raise an `OverflowError` that names nothing).
pub(crate) fn unsigned<T: TryFrom<u64>>(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<T> {
    if !obj.is_instance_of::<PyInt>() {
        return Err(PyTypeError::new_err(format!(
            "{name} must be an integer, got {}",
            obj.get_type().name()?
        )));
    }
    if obj.lt(0)? {
        return Err(PyValueError::new_err(format!(
            "{name} must be >= 0, got {obj}"
        )));
    }
    obj.extract::<u64>()
        .ok()
        .and_then(|v| T::try_from(v).ok())
        .ok_or_else(|| PyValueError::new_err(format!("{name} = {obj} is too large")))
}
