//! `FitnessSpec`: what `evaluate`, `optimize` and `held_out` compare and how (the searched paths, the
//! pixels, the loss, its norm and space, the closed form's bounds), read from Python's keyword arguments
//! and checked once, each error one line naming its field. A call pairs it with a scene and a target
//! ([`PyFitnessSpec::args`]), which checks only what depends on them.

use numpy::{PyReadonlyArray1, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::prelude::*;

use super::fitness::{check_image_shape, FitnessArgs};
use crate::error::Error;
use crate::fitness::{FitnessSpec, LossKind, Norm, Projection, Space};
use crate::params::ParamLayout;
use crate::scene::Scene;

/// A fitness's arguments (immutable), built once per fit stage and passed to every native call of it.
#[pyclass(frozen, name = "FitnessSpec", module = "rtloop._native")]
pub struct PyFitnessSpec {
    paths: Vec<String>,
    spec: FitnessSpec,
    frozen_bounce: usize,
    /// `loss`, `norm` and `space` as given.
    names: [String; 3],
}

/// `value` as a `T`, else an error "`name`: must be `want` (got ...)".
fn field<'a, 'py, T: FromPyObject<'a, 'py>>(
    name: &str,
    value: &'a Bound<'py, PyAny>,
    want: &str,
) -> PyResult<T> {
    value.extract::<T>().map_err(|_| {
        let got = match (value.getattr("dtype"), value.getattr("shape")) {
            (Ok(dtype), Ok(shape)) if shape.len().is_ok_and(|n| n == 0) => {
                format!("a {dtype} scalar")
            }
            (Ok(dtype), Ok(shape)) => format!("a {dtype} array of shape {shape}"),
            _ => match value.get_type().name() {
                Ok(t) => t.to_string(),
                Err(_) => "another type".to_string(),
            },
        };
        Error::Invalid(format!("{name}: must be {want} (got {got})")).into()
    })
}

/// The closed form's bounds from `product_bounds` (objects, 3 | 4 | 7, 2): rows 0-2 the diffuse
/// products, row 3 Q = intensity x specular, rows 4-6 exposure x environment x albedo.
fn projection(b: &Bound<'_, PyAny>) -> PyResult<Projection> {
    let want = "a float64 array of shape (objects, 3, 2), (objects, 4, 2) or (objects, 7, 2)";
    let b: PyReadonlyArray3<'_, f64> = field("product_bounds", b, want)?;
    let a = b.as_array();
    let (n, rows) = (a.shape()[0], a.shape()[1]);
    if ![3, 4, 7].contains(&rows) || a.shape()[2] != 2 {
        let msg = format!("product_bounds: must be {want} (got shape {:?})", a.shape());
        return Err(Error::Invalid(msg).into());
    }
    for (k, r) in (0..n).flat_map(|k| (0..rows).map(move |r| (k, r))) {
        let (lo, hi) = (a[[k, r, 0]], a[[k, r, 1]]);
        if lo.is_nan() || hi.is_nan() || lo > hi {
            let msg =
                format!("product_bounds: object {k} row {r} is ({lo}, {hi}); needs low <= high");
            return Err(Error::Invalid(msg).into());
        }
    }
    let mut proj = Projection::matte(
        (0..n)
            .map(|k| std::array::from_fn(|c| (a[[k, c, 0]], a[[k, c, 1]])))
            .collect(),
    );
    if rows >= 4 {
        proj.specular = (0..n).map(|k| (a[[k, 3, 0]], a[[k, 3, 1]])).collect();
    }
    if rows == 7 {
        proj.environment = (0..n)
            .map(|k| std::array::from_fn(|c| (a[[k, 4 + c, 0]], a[[k, 4 + c, 1]])))
            .collect();
    }
    Ok(proj)
}

#[pymethods]
impl PyFitnessSpec {
    /// `paths`: the searched parameters (in the scene's fit section). `pixels`: the pixel indices the
    /// loss counts (uint32; None: all). `loss`: "l1", "l1_rgb" or "l1_projected" (the closed form, which
    /// needs `product_bounds`). `norm`: "l1", "l2", "huber" or "huber:H"; `space`: "linear" or "srgb".
    /// `footprint`: pixels integrated over their area. `frozen_bounce`: with interreflection, 0 the full
    /// bounce; for `evaluate` and `held_out` N >= 1 holds it at the scene's own values, for `optimize` N
    /// passes (see its docstring). `saturated`: the level from which values may be clipped (> 0; None:
    /// the default). `solve_margin`: the Chebyshev distance to another object's pixels below which a
    /// pixel does not inform the closed-form products.
    #[new]
    #[pyo3(signature = (paths, *, pixels=None, loss=None, clip=None, product_bounds=None, norm=None,
                        space=None, footprint=None, frozen_bounce=None, saturated=None,
                        solve_margin=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        paths: &Bound<'_, PyAny>,
        pixels: Option<&Bound<'_, PyAny>>,
        loss: Option<&Bound<'_, PyAny>>,
        clip: Option<&Bound<'_, PyAny>>,
        product_bounds: Option<&Bound<'_, PyAny>>,
        norm: Option<&Bound<'_, PyAny>>,
        space: Option<&Bound<'_, PyAny>>,
        footprint: Option<&Bound<'_, PyAny>>,
        frozen_bounce: Option<&Bound<'_, PyAny>>,
        saturated: Option<&Bound<'_, PyAny>>,
        solve_margin: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyFitnessSpec> {
        let text = |name: &str, v: Option<&Bound<'_, PyAny>>, default: &str| match v {
            Some(v) => field::<String>(name, v, "a string"),
            None => Ok(default.to_string()),
        };
        let flag = |name: &str, v: Option<&Bound<'_, PyAny>>, default: bool| match v {
            Some(v) => field::<bool>(name, v, "True or False"),
            None => Ok(default),
        };
        let count = |name: &str, v: Option<&Bound<'_, PyAny>>| match v {
            Some(v) => field::<usize>(name, v, "an integer >= 0"),
            None => Ok(0),
        };
        let paths: Vec<String> = field("paths", paths, "a list of parameter paths (strings)")?;
        let names = [
            text("loss", loss, "l1")?,
            text("norm", norm, "l1")?,
            text("space", space, "linear")?,
        ];
        let kind = LossKind::parse(&names[0]).map_err(|e| Error::Invalid(format!("loss: {e}")))?;
        let norm_kind = Norm::parse(&names[1]).map_err(|e| Error::Invalid(format!("norm: {e}")))?;
        let space_kind = Space::parse(&names[2]).map_err(Error::Invalid)?;
        let pixels = match pixels {
            Some(p) => {
                let want = "a 1-D uint32 array of pixel indices";
                let p: PyReadonlyArray1<'_, u32> = field("pixels", p, want)?;
                Some(p.as_array().to_vec())
            }
            None => None,
        };
        let saturated = match saturated {
            Some(s) => Some(field::<f32>("saturated", s, "a number")?),
            None => None,
        };
        if let Some(level) = saturated.filter(|l| !l.is_finite() || *l <= 0.0) {
            let msg = format!("saturated: must be a number in (0, 1] (got {level})");
            return Err(Error::Invalid(msg).into());
        }
        let spec = FitnessSpec {
            pixels,
            loss: kind,
            clip: flag("clip", clip, true)?,
            projection: product_bounds.map(projection).transpose()?,
            footprint: flag("footprint", footprint, false)?,
            solve_margin: count("solve_margin", solve_margin)?,
            norm: norm_kind,
            space: space_kind,
            saturated,
            // a search's own options (`optimize`'s `silhouettes`), not the spec's
            outlines: false,
            outline_gate: false,
        };
        let frozen_bounce = count("frozen_bounce", frozen_bounce)?;
        Ok(PyFitnessSpec {
            paths,
            spec,
            frozen_bounce,
            names,
        })
    }

    fn __repr__(&self) -> String {
        let s = &self.spec;
        format!(
            "<rtloop.FitnessSpec paths={:?}, loss={:?}, norm={:?}, space={:?}, {} pixels, clip={}, \
             footprint={}, frozen_bounce={}, saturated={:?}, solve_margin={}>",
            self.paths,
            self.names[0],
            self.names[1],
            self.names[2],
            s.pixels.as_ref().map_or("all".to_string(), |p| p.len().to_string()),
            s.clip,
            s.footprint,
            self.frozen_bounce,
            s.saturated,
            s.solve_margin
        )
    }
}

impl PyFitnessSpec {
    /// With interreflection: the passes holding the bounce (0: none).
    pub(super) fn frozen_bounce_passes(&self) -> usize {
        self.frozen_bounce
    }

    pub(super) fn loss_kind(&self) -> LossKind {
        self.spec.loss
    }

    /// The pixels the loss counts (None: all).
    pub(super) fn pixels(&self) -> Option<&[u32]> {
        self.spec.pixels.as_deref()
    }

    /// The fitness's arguments for `scene` against `target` (H, W, 3): the paths must be in the scene's
    /// fit section and `product_bounds` hold one row per object of the scene.
    pub(super) fn args(
        &self,
        scene: &Scene,
        target: &PyReadonlyArray3<'_, f32>,
    ) -> PyResult<FitnessArgs> {
        let layout = ParamLayout::new(scene, &self.paths)?;
        check_image_shape(scene, target.shape(), |shape, h, w| {
            format!("objective image has shape {shape:?}; the scene needs ({h}, {w}, 3)")
        })?;
        let target = match target.as_slice() {
            Ok(s) => s.to_vec(),
            Err(_) => target.as_array().iter().copied().collect(),
        };
        if let Some(proj) = &self.spec.projection {
            let n = scene.objects.len();
            if proj.diffuse.len() != n {
                let msg = format!(
                    "product_bounds has {} objects; the scene has {n} (one row per object)",
                    proj.diffuse.len()
                );
                return Err(Error::Invalid(msg).into());
            }
        }
        Ok(FitnessArgs {
            layout,
            target,
            spec: self.spec.clone(),
        })
    }
}
