//! The thin pyo3 binding of translucent-core: converts numpy arrays and Python values to core
//! types, releases the GIL around long work, and maps core errors to Python exceptions.
//! No maths lives here.

use pyo3::prelude::*;

mod call;
mod convert;
mod evaluation;
mod hierarchy;
mod material;
mod prt;
mod reference;
mod scene;
mod splat;

/// mimalloc keeps freed pages for the next call: an edit allocates a few megabytes per call at
/// 120k vertices, and the system allocator returned them to the kernel each time, so every
/// edit paid the page faults again (measured 2 ms of a 10 ms textured edit on this machine).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// The native module; the pure-Python package `translucent` re-exports it.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("Cancelled", m.py().get_type::<convert::Cancelled>())?;
    // The stated limits on request sizes (docs/api.md, "Limits"), by name.
    let limits = pyo3::types::PyDict::new(m.py());
    for l in translucent_core::limits::ALL {
        if l.value.fract() == 0.0 {
            limits.set_item(l.name, l.value as u64)?;
        } else {
            limits.set_item(l.name, l.value)?;
        }
    }
    m.add("LIMITS", limits)?;
    // Cycles' clamps of the random walk's inputs (`optics::principled`), by name.
    use translucent_core::optics::principled as p;
    let clamps = pyo3::types::PyDict::new(m.py());
    clamps.set_item("anisotropy", p::G_RANGE)?;
    clamps.set_item("ior", p::IOR_RANGE)?;
    clamps.set_item("albedo", (p::MIN_ALBEDO, p::MAX_ALBEDO))?;
    m.add("CYCLES_CLAMPS", clamps)?;
    m.add_class::<material::PyMaterial>()?;
    m.add_class::<scene::PyScene>()?;
    m.add_class::<prt::PyPrt>()?;
    m.add_class::<hierarchy::PyHierarchy>()?;
    m.add_class::<splat::PySplat>()?;
    m.add_function(wrap_pyfunction!(reference::reference_radiosity_py, m)?)?;
    m.add_function(wrap_pyfunction!(reference::reference_radiance_py, m)?)?;
    m.add_function(wrap_pyfunction!(reference::relative_error, m)?)?;
    m.add_function(wrap_pyfunction!(
        reference::reference_single_scattering_py,
        m
    )?)?;
    m.add_function(wrap_pyfunction!(material::prepare_profile, m)?)?;
    m.add_function(wrap_pyfunction!(material::profile_ready, m)?)?;
    m.add_function(wrap_pyfunction!(material::set_table_cache, m)?)?;
    m.add_function(wrap_pyfunction!(material::table_cache, m)?)?;
    m.add_function(wrap_pyfunction!(material::single_scattering_albedo, m)?)?;
    m.add_function(wrap_pyfunction!(material::layer_weight, m)?)?;
    m.add_function(wrap_pyfunction!(material::principled_for_medium, m)?)?;
    Ok(())
}
