//! The exceptions of `pyfoc`: `PyfocError` (a `ValueError`) and its kinds. `LogError` (a
//! recorded log that cannot be read) is in `replay`.

use pyo3::create_exception;
use pyo3::exceptions::PyValueError;

create_exception!(
    pyfoc,
    PyfocError,
    PyValueError,
    "Base class of pyfoc's errors (a ValueError)."
);
create_exception!(
    pyfoc,
    ConfigError,
    PyfocError,
    "Invalid motor or filter parameters; the message gives the reason."
);
create_exception!(
    pyfoc,
    SimulationError,
    PyfocError,
    "The simulator could not run the scenario (e.g. its controller could not be built)."
);
create_exception!(
    pyfoc,
    FilterError,
    PyfocError,
    "A filter operation was refused (e.g. a non-finite reset); the filter is unchanged."
);
