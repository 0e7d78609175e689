//! Conversions between Python/numpy values and core types, and core errors to exceptions.

use pyo3::exceptions::{PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use translucent_core::Error;

pyo3::create_exception!(
    _native,
    Cancelled,
    PyRuntimeError,
    "The computation was cancelled by its progress callback."
);

/// Runs core work so that a panic (a bug, never bad input) becomes a RuntimeError naming it,
/// not a `PanicException` (a BaseException that `except Exception` would not catch).
pub fn guard<T>(work: impl FnOnce() -> Result<T, Error>) -> Result<T, GuardError> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(work)) {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(GuardError::Core(e)),
        Err(payload) => {
            let msg = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            Err(GuardError::Panic(msg))
        }
    }
}

/// A core error, or a caught panic.
pub enum GuardError {
    Core(Error),
    Panic(String),
}

/// Every user-caused core error is a ValueError naming what was wrong; cancelling is `Cancelled`.
pub fn to_py(err: Error) -> PyErr {
    match err {
        Error::Cancelled => Cancelled::new_err(err.to_string()),
        Error::GpuUnavailable(_) => PyRuntimeError::new_err(err.to_string()),
        _ => PyValueError::new_err(err.to_string()),
    }
}

/// An RGB triple from a float (grey) or a sequence of three floats.
pub fn rgb(name: &str, value: &Bound<'_, PyAny>) -> PyResult<[f64; 3]> {
    if let Ok(x) = value.extract::<f64>() {
        return Ok([x; 3]);
    }
    let v: Vec<f64> = value.extract().map_err(|_| {
        PyValueError::new_err(format!("{name} must be a float or a sequence of 3 floats"))
    })?;
    <[f64; 3]>::try_from(v.as_slice()).map_err(|_| {
        PyValueError::new_err(format!(
            "{name} must have 3 components (RGB), got {}",
            v.len()
        ))
    })
}

use numpy::{PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use translucent_core::Vec3;

fn as_contiguous<'py>(value: &Bound<'py, PyAny>, dtype: &str) -> PyResult<Bound<'py, PyAny>> {
    let np = value.py().import("numpy")?;
    np.call_method1("ascontiguousarray", (value, dtype))
}

/// An (N, 3) float array as f32 rows. Read in double precision first so that a finite value
/// beyond f32's range (1e39 in a float64 array) is refused here, saying so, instead of reaching
/// the core as an infinity; NaN and infinities given as such are the core's to report.
pub fn float_rows(name: &str, value: &Bound<'_, PyAny>) -> PyResult<Vec<[f32; 3]>> {
    // A C-contiguous (N, 3) float32 array (what the add-on passes at every edit) is read as it
    // is: one copy, none of the float64 round trip (0.6 ms of an edit at 139k rows).
    if let Ok(arr) = value.extract::<PyReadonlyArray2<f32>>() {
        if arr.shape()[1] == 3 {
            if let Ok(s) = arr.as_slice() {
                return Ok(s.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect());
            }
        }
    }
    let arr = as_contiguous(value, "float64")
        .map_err(|e| PyValueError::new_err(format!("{name} must be an (N, 3) float array: {e}")))?;
    let arr: PyReadonlyArray2<f64> = arr
        .extract()
        .map_err(|_| PyValueError::new_err(format!("{name} must be a 2-D (N, 3) float array")))?;
    if arr.shape()[1] != 3 {
        return Err(PyValueError::new_err(format!(
            "{name} must have shape (N, 3), got {:?}",
            arr.shape()
        )));
    }
    let s = arr.as_slice()?;
    if let Some(i) = s
        .iter()
        .position(|v| v.is_finite() && v.abs() > f64::from(f32::MAX))
    {
        return Err(PyValueError::new_err(format!(
            "{name} row {} holds {:e}, which overflows single precision (|x| <= {:e}); \
             scale the scene down",
            i / 3,
            s[i],
            f32::MAX
        )));
    }
    Ok(s.chunks_exact(3)
        .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32])
        .collect())
}

/// A (T, 3, 3) float array (per triangle, its three corners' RGB) as f32 blocks; the range is
/// the core's to check.
pub fn corner_rows(name: &str, value: &Bound<'_, PyAny>) -> PyResult<Vec<[[f32; 3]; 3]>> {
    let arr = as_contiguous(value, "float64").map_err(|e| {
        PyValueError::new_err(format!("{name} must be a (T, 3, 3) float array: {e}"))
    })?;
    let shape: Vec<usize> = arr.getattr("shape")?.extract()?;
    if shape.len() != 3 || shape[1] != 3 || shape[2] != 3 {
        return Err(PyValueError::new_err(format!(
            "{name} must have shape (T, 3, 3): per triangle, its three corners' RGB; got {shape:?}"
        )));
    }
    let rows = float_rows(name, &arr.call_method1("reshape", ((-1i64, 3i64),))?)?;
    Ok(rows.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// A 1-D float array as f32 values (read in double precision, as `float_rows`); the range is
/// the core's to check.
pub fn float_values(name: &str, value: &Bound<'_, PyAny>) -> PyResult<Vec<f32>> {
    let arr = as_contiguous(value, "float64")
        .map_err(|e| PyValueError::new_err(format!("{name} must be an (N,) float array: {e}")))?;
    let arr: PyReadonlyArray1<f64> = arr
        .extract()
        .map_err(|_| PyValueError::new_err(format!("{name} must be a 1-D (N,) float array")))?;
    Ok(arr.as_slice()?.iter().map(|&v| v as f32).collect())
}

/// An (N, 3) float array as Vec3.
pub fn vec3_array(name: &str, value: &Bound<'_, PyAny>) -> PyResult<Vec<Vec3>> {
    Ok(float_rows(name, value)?
        .into_iter()
        .map(Vec3::from)
        .collect())
}

/// An `update`'s pose: `positions` (N, 3) and optional `normals` (N, 3), or None without
/// positions; normals without positions are a ValueError.
#[allow(clippy::type_complexity)]
pub fn pose(
    positions: Option<&Bound<'_, PyAny>>,
    normals: Option<&Bound<'_, PyAny>>,
) -> PyResult<Option<(Vec<Vec3>, Option<Vec<Vec3>>)>> {
    let Some(p) = positions else {
        if normals.is_some() {
            return Err(PyValueError::new_err(
                "normals need positions (a pose): update(positions=..., normals=...)",
            ));
        }
        return Ok(None);
    };
    let p = vec3_array("positions", p)?;
    let n = normals.map(|n| vec3_array("normals", n)).transpose()?;
    Ok(Some((p, n)))
}

/// A count or index argument taken as i64 (so that a negative value reaches us instead of
/// pyo3's OverflowError) and checked here: ValueError naming the argument.
pub fn non_negative<T: TryFrom<i64>>(name: &str, value: i64) -> PyResult<T> {
    if value < 0 {
        return Err(PyValueError::new_err(format!(
            "{name} = {value} must be >= 0"
        )));
    }
    T::try_from(value).map_err(|_| PyValueError::new_err(format!("{name} = {value} is too large")))
}

/// An (M, 3) integer array of vertex indices, checked non-negative and below 2^32. Anything
/// but an integer dtype is a TypeError: numpy's cast would truncate 1.7 to vertex 1 silently.
pub fn triangle_array(name: &str, value: &Bound<'_, PyAny>) -> PyResult<Vec<[u32; 3]>> {
    let np = value.py().import("numpy")?;
    let given = np.call_method1("asarray", (value,)).map_err(|e| {
        PyValueError::new_err(format!("{name} must be an (M, 3) integer array: {e}"))
    })?;
    let dtype = given.getattr("dtype")?;
    let kind: String = dtype.getattr("kind")?.extract()?;
    let size: usize = given.getattr("size")?.extract()?;
    // An empty array has nothing to truncate (`[]` is float64 to numpy): the core reports it.
    if size > 0 && kind != "i" && kind != "u" {
        return Err(PyTypeError::new_err(format!(
            "{name} must be an integer array of vertex indices, got dtype {}; \
             convert whole-number floats with .astype(np.int64) after checking them",
            dtype.str()?
        )));
    }
    let arr = as_contiguous(&given, "int64").map_err(|e| {
        PyValueError::new_err(format!("{name} must be an (M, 3) integer array: {e}"))
    })?;
    let arr: PyReadonlyArray2<i64> = arr
        .extract()
        .map_err(|_| PyValueError::new_err(format!("{name} must be a 2-D (M, 3) integer array")))?;
    if arr.shape()[1] != 3 {
        return Err(PyValueError::new_err(format!(
            "{name} must have shape (M, 3), got {:?}",
            arr.shape()
        )));
    }
    let s = arr.as_slice()?;
    if let Some(i) = s.iter().position(|&v| v < 0 || v > i64::from(u32::MAX)) {
        return Err(PyValueError::new_err(format!(
            "{name}: triangle {} has index {} out of range",
            i / 3,
            s[i]
        )));
    }
    Ok(s.chunks_exact(3)
        .map(|t| [t[0] as u32, t[1] as u32, t[2] as u32])
        .collect())
}

/// A 3-vector from any sequence of three numbers; a finite component beyond single precision
/// (1e39) is refused naming `name` instead of becoming an infinity.
pub fn vec3(name: &str, value: &Bound<'_, PyAny>) -> PyResult<Vec3> {
    let v = rgb(name, value)?;
    if let Some(x) = v
        .iter()
        .find(|x| x.is_finite() && x.abs() > f64::from(f32::MAX))
    {
        return Err(PyValueError::new_err(format!(
            "{name} has a component {x:e}, which overflows single precision (|x| <= {:e})",
            f32::MAX
        )));
    }
    Ok(Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32))
}

/// A direction from any sequence of three numbers, normalised in double precision first (so
/// (-1e30, 0, 0) or (1e39, 0, 0) is the direction -X or +X); the core checks the rest.
pub fn direction(name: &str, value: &Bound<'_, PyAny>) -> PyResult<Vec3> {
    let v = rgb(name, value)?;
    // Scaled by the largest component first, so no square overflows.
    let m = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let u = if m.is_finite() && m > 0.0 {
        let s = v.map(|x| x / m);
        let len = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt();
        s.map(|x| x / len)
    } else {
        v
    };
    Ok(Vec3::new(u[0] as f32, u[1] as f32, u[2] as f32))
}

/// The eye of a radiance evaluation: three numbers within the core's coordinate range for
/// points off the mesh (`lights::POINT_LIMIT`), ValueError naming `eye` otherwise.
pub fn eye(value: Option<&Bound<'_, PyAny>>) -> PyResult<Option<Vec3>> {
    value
        .filter(|v| !v.is_none())
        .map(|v| {
            let e = vec3("eye", v)?;
            translucent_core::lights::check_point("eye", e).map_err(to_py)
        })
        .transpose()
}

fn describe(value: &Bound<'_, PyAny>) -> String {
    let kind = value
        .get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "object".into());
    let repr = value
        .repr()
        .map(|r| r.to_string())
        .unwrap_or_else(|_| "?".into());
    let repr = if repr.len() > 60 {
        format!("{}...", &repr[..57])
    } else {
        repr
    };
    format!("{kind} {repr}")
}

/// An integer argument (`#[pyo3(from_py_with = ...)]`): a Python int or numpy integer, not a
/// bool or a float, within 64 bits. Its errors are TypeErrors, which pyo3 prefixes with the
/// argument's name ("argument 'walks': ..."); ranges are checked by `non_negative`.
pub fn int(value: &Bound<'_, PyAny>) -> PyResult<i64> {
    use pyo3::exceptions::PyOverflowError;
    use pyo3::types::{PyBool, PyFloat};
    if value.is_instance_of::<PyBool>() || value.is_instance_of::<PyFloat>() {
        return Err(PyTypeError::new_err(format!(
            "expected an integer, got {}",
            describe(value)
        )));
    }
    value.extract::<i64>().map_err(|e| {
        if e.is_instance_of::<PyOverflowError>(value.py()) {
            PyTypeError::new_err(format!(
                "expected an integer that fits 64 bits (|n| < 2^63), got {}",
                describe(value)
            ))
        } else {
            PyTypeError::new_err(format!("expected an integer, got {}", describe(value)))
        }
    })
}

/// An optional integer argument (`from_py_with`): None, or as `int`.
pub fn opt_int(value: &Bound<'_, PyAny>) -> PyResult<Option<i64>> {
    if value.is_none() {
        return Ok(None);
    }
    int(value).map(Some)
}

/// A pair of floats (`from_py_with`), e.g. `eps = (receiver, emitter)`; TypeError (named by
/// pyo3) for anything else.
pub fn float_pair(value: &Bound<'_, PyAny>) -> PyResult<(f64, f64)> {
    let v: Vec<f64> = value.extract().map_err(|_| {
        PyTypeError::new_err(format!("expected two floats, got {}", describe(value)))
    })?;
    <[f64; 2]>::try_from(v.as_slice())
        .map(|[a, b]| (a, b))
        .map_err(|_| {
            PyTypeError::new_err(format!(
                "expected two floats, got {} value(s): {}",
                v.len(),
                describe(value)
            ))
        })
}

/// A progress callback (`from_py_with`): None or a callable taking a fraction in [0, 1];
/// anything else is a TypeError now (named by pyo3), not when the first call would fail.
pub fn callback(value: &Bound<'_, PyAny>) -> PyResult<Option<Py<PyAny>>> {
    if value.is_none() {
        return Ok(None);
    }
    if !value.is_callable() {
        return Err(PyTypeError::new_err(format!(
            "expected a callable taking a fraction in [0, 1] (return False to cancel) or None, \
             got {}",
            describe(value)
        )));
    }
    Ok(Some(value.clone().unbind()))
}

/// Receiver vertex indices `name`: a sequence or integer array of ints, each in [0, n).
/// A string ("0,5"), a lone number (5) or a float (1.5) is a TypeError saying what is wanted;
/// an index out of range a ValueError naming it.
pub fn receiver_indices(
    name: &str,
    value: Option<&Bound<'_, PyAny>>,
    n: usize,
) -> PyResult<Option<Vec<u32>>> {
    use pyo3::types::{PyBytes, PyString};
    let Some(value) = value.filter(|v| !v.is_none()) else {
        return Ok(None);
    };
    let wanted = format!("{name} must be integer vertex indices (a sequence or integer array)");
    if value.is_instance_of::<PyString>() || value.is_instance_of::<PyBytes>() {
        return Err(PyTypeError::new_err(format!(
            "{wanted}, got {}; parse the text first",
            describe(value)
        )));
    }
    let items = value.try_iter().map_err(|_| {
        PyTypeError::new_err(format!(
            "{wanted}, got {}; write [i] for one vertex",
            describe(value)
        ))
    })?;
    let mut out = Vec::new();
    for (k, item) in items.enumerate() {
        let item = item?;
        let i = int(&item).map_err(|_| {
            PyTypeError::new_err(format!("{wanted}: item {k} is {}", describe(&item)))
        })?;
        if !(0..n as i64).contains(&i) {
            return Err(PyValueError::new_err(format!(
                "{name}[{k}] = {i}: receiver index out of range for {n} vertices (0..{})",
                n.saturating_sub(1)
            )));
        }
        out.push(i as u32);
    }
    Ok(Some(out))
}

/// Per-vertex RGB values as an (N, 3) float32 numpy array.
pub fn rgb_array<'py>(py: Python<'py>, values: &[[f32; 3]]) -> Bound<'py, PyArray2<f32>> {
    let flat: Vec<f32> = values.iter().flatten().copied().collect();
    numpy::ndarray::Array2::from_shape_vec((values.len(), 3), flat)
        .map(|a| PyArray2::from_owned_array(py, a))
        .expect("shape matches length")
}

/// (N, 3) float32 rows of points or directions.
pub fn vec3_rows<'py>(py: Python<'py>, values: &[Vec3]) -> Bound<'py, PyArray2<f32>> {
    let flat: Vec<f32> = values.iter().flat_map(|v| v.to_array()).collect();
    numpy::ndarray::Array2::from_shape_vec((values.len(), 3), flat)
        .map(|x| PyArray2::from_owned_array(py, x))
        .expect("three per row")
}

/// The walks' term and own light's settings (`surface_terms`) from a method's `walks` and
/// `walk_rays` arguments: None with the walks off; ValueError naming `walk_rays` when it is
/// given with the walks off, or 0.
pub fn term_settings(
    walks: bool,
    walk_rays: Option<i64>,
    vertices: usize,
) -> PyResult<Option<translucent_core::surface_terms::TermSettings>> {
    if walk_rays.is_some() && !walks {
        return Err(PyValueError::new_err(
            "walk_rays: the walks are off (walks=False)",
        ));
    }
    if !walks {
        return Ok(None);
    }
    let rays = match walk_rays {
        Some(r) => {
            let r: u64 = non_negative("walk_rays", r)?;
            if r == 0 {
                return Err(PyValueError::new_err(
                    "walk_rays 0: leave walks off instead",
                ));
            }
            r
        }
        None => translucent_core::walks::default_walk_rays(vertices),
    };
    Ok(Some(translucent_core::surface_terms::TermSettings {
        walks: translucent_core::walks::WalkTermSettings {
            rays,
            ..Default::default()
        },
        // PRT's default own light: 144 rays a vertex.
        interreflection: Some(
            (translucent_core::own_light::DEFAULT_RAYS as f64)
                .sqrt()
                .round() as usize,
        ),
    }))
}
