//! The native `Scene` class: a validated, immutable scene and its parameter views.

use pyo3::prelude::*;
use pyo3::types::PyDict;
use serde_json::json;

use crate::error::Error;
use crate::params::ParamLayout;
use crate::scene::Scene;

/// A validated scene (immutable). Build one with `Scene(json_text)`; `rtloop.load_scene` is the friendly way.
#[pyclass(frozen, name = "Scene", module = "rtloop._native")]
pub struct PyScene(pub Scene);

#[pymethods]
impl PyScene {
    /// `base_dir`: the folder relative mesh files are read from (the current directory when omitted).
    #[new]
    #[pyo3(signature = (json_text, base_dir=None))]
    fn new(json_text: &str, base_dir: Option<std::path::PathBuf>) -> PyResult<Self> {
        Ok(PyScene(Scene::from_json_in(
            json_text,
            base_dir.as_deref(),
        )?))
    }

    #[getter]
    fn width(&self) -> u32 {
        self.0.width
    }

    #[getter]
    fn height(&self) -> u32 {
        self.0.height
    }

    /// Object names in scene order.
    #[getter]
    fn object_names(&self) -> Vec<String> {
        self.0.objects.iter().map(|o| o.name.clone()).collect()
    }

    /// The fit section's paths in canonical order.
    #[getter]
    fn fit_paths(&self) -> Vec<String> {
        self.0.fit.iter().map(|f| f.path.clone()).collect()
    }

    /// Scalar parameter names (e.g. `light.position.x`) for `paths` (all fit paths when omitted).
    #[pyo3(signature = (paths=None))]
    fn param_names(&self, paths: Option<Vec<String>>) -> PyResult<Vec<String>> {
        Ok(layout(&self.0, paths)?.names)
    }

    /// (min, max) per scalar parameter.
    #[pyo3(signature = (paths=None))]
    fn bounds(&self, paths: Option<Vec<String>>) -> PyResult<Vec<(f64, f64)>> {
        Ok(layout(&self.0, paths)?.bounds)
    }

    /// Current values of the scalar parameters.
    #[pyo3(signature = (paths=None))]
    fn get_params(&self, paths: Option<Vec<String>>) -> PyResult<Vec<f64>> {
        let l = layout(&self.0, paths)?;
        Ok(l.read(&self.0))
    }

    /// A copy with the scalar parameters of `paths` set to `values` (no bounds check: bounds are the search's).
    #[pyo3(signature = (values, paths=None))]
    fn with_params(&self, values: Vec<f64>, paths: Option<Vec<String>>) -> PyResult<PyScene> {
        let l = layout(&self.0, paths)?;
        if values.len() != l.dim() {
            return Err(
                Error::Value(format!("expected {} values, got {}", l.dim(), values.len())).into(),
            );
        }
        if let Some(v) = values.iter().find(|v| !v.is_finite()) {
            return Err(Error::Value(format!("parameter values must be finite (got {v})")).into());
        }
        let mut s = self.0.clone();
        l.apply(&mut s, &values);
        Ok(PyScene(s))
    }

    /// A copy with new fit bounds: `changes` maps a fit path to `(min, max)`, each a number or one per
    /// component (a path not in the fit section is added). Validated as `Scene(json_text)` validates.
    fn with_bounds(&self, changes: &Bound<'_, PyDict>) -> PyResult<PyScene> {
        let mut list = Vec::with_capacity(changes.len());
        for (path, bounds) in changes.iter() {
            let path: String = path.extract()?;
            let (min, max): (Limit, Limit) = bounds.extract()?;
            let field = |side: &str| format!("fit.{path}.{side}");
            let bounds =
                json!({"min": min.value(&field("min"))?, "max": max.value(&field("max"))?});
            list.push((path, bounds));
        }
        Ok(PyScene(self.0.with_bounds(&list)?))
    }

    /// A copy with `other`'s fit section (checked against this scene's objects and light).
    fn with_fit(&self, other: &Bound<'_, PyScene>) -> PyResult<PyScene> {
        Ok(PyScene(self.0.with_fit(&other.get().0)?))
    }

    /// A copy with an empty fit section.
    fn without_fit(&self) -> PyScene {
        PyScene(self.0.without_fit())
    }

    /// The scene as JSON text in the public format, defaults written out.
    fn to_json(&self) -> String {
        serde_json::to_string_pretty(&self.0.to_value()).expect("a scene always serialises")
    }

    /// The scene as a plain dict in the public format (defaults written out): what `json.loads` makes of
    /// `to_json()`, built without the text.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_python(py, &self.0.to_value())
    }

    fn __repr__(&self) -> String {
        format!(
            "<rtloop.Scene {}x{}, {} objects, {} free parameters>",
            self.0.width,
            self.0.height,
            self.0.objects.len(),
            ParamLayout::all(&self.0).dim()
        )
    }
}

/// `value` as the Python object `json.loads` makes of its JSON text, the same to the last bit: objects
/// as dicts in the text's key order, arrays as lists, integers as int, other numbers as float (the text
/// is their shortest round-trip form, so `json.loads` reads back the very f64), null as None.
fn json_to_python<'py>(py: Python<'py>, value: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    use pyo3::types::{PyBool, PyFloat, PyList, PyString};
    use serde_json::Value;
    Ok(match value {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => PyBool::new(py, *b).to_owned().into_any(),
        Value::Number(n) => match (n.as_i64(), n.as_u64()) {
            (Some(i), _) => i.into_pyobject(py)?.into_any(),
            (None, Some(u)) => u.into_pyobject(py)?.into_any(),
            (None, None) => PyFloat::new(py, n.as_f64().unwrap_or(f64::NAN)).into_any(),
        },
        Value::String(s) => PyString::new(py, s).into_any(),
        Value::Array(items) => {
            let list = PyList::empty(py);
            for item in items {
                list.append(json_to_python(py, item)?)?;
            }
            list.into_any()
        }
        Value::Object(map) => {
            let dict = PyDict::new(py);
            for (k, v) in map {
                dict.set_item(k, json_to_python(py, v)?)?;
            }
            dict.into_any()
        }
    })
}

/// One side of a bound pair: one number or one per component.
#[derive(FromPyObject)]
enum Limit {
    One(f64),
    Each(Vec<f64>),
}

impl Limit {
    /// The JSON value; a NaN or infinity is an error naming `field` as `load_scene` names it.
    fn value(&self, field: &str) -> Result<serde_json::Value, Error> {
        let bad = |at: String| {
            Error::Scene(format!(
                "{at}: must be a finite number (got NaN or infinity)"
            ))
        };
        match self {
            Limit::One(v) if !v.is_finite() => Err(bad(field.to_string())),
            Limit::One(v) => Ok(json!(v)),
            Limit::Each(v) => match v.iter().position(|x| !x.is_finite()) {
                Some(k) => Err(bad(format!("{field}[{k}]"))),
                None => Ok(json!(v)),
            },
        }
    }
}

fn layout(scene: &Scene, paths: Option<Vec<String>>) -> PyResult<ParamLayout> {
    Ok(match paths {
        Some(p) => ParamLayout::new(scene, &p)?,
        None => ParamLayout::all(scene),
    })
}
