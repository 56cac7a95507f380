//! rtloop's Python exceptions and the one conversion of the core's [`Error`] into them.

use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::PyErr;

use crate::error::Error;

create_exception!(
    _native,
    RtloopError,
    PyException,
    "Base class of rtloop's errors."
);
create_exception!(
    _native,
    SceneError,
    RtloopError,
    "The scene description is invalid; the message names the field."
);

impl From<Error> for PyErr {
    fn from(e: Error) -> PyErr {
        match e {
            Error::Scene(m) => SceneError::new_err(m),
            Error::Invalid(m) => RtloopError::new_err(m),
            Error::Value(m) => PyValueError::new_err(m),
            Error::Io { .. } => RtloopError::new_err(e.to_string()),
        }
    }
}
