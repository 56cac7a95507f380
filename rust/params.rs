//! Free parameters: a selection of the scene's fit paths laid out as one flat `f64` vector.

use crate::error::{Error, Result};
use crate::scene::Scene;
pub use crate::scene::{Target, FITTABLE};

/// A selection of the scene's fit parameters laid out as one vector.
#[derive(Clone, Debug)]
pub struct ParamLayout {
    pub entries: Vec<(String, Target, usize)>,
    pub bounds: Vec<(f64, f64)>,
    pub names: Vec<String>,
}

impl ParamLayout {
    /// Select `paths` (each must appear in the scene's `fit` section) in canonical order.
    pub fn new(scene: &Scene, paths: &[String]) -> Result<ParamLayout> {
        for p in paths {
            if !scene.fit.iter().any(|f| &f.path == p) {
                let known: Vec<&str> = scene.fit.iter().map(|f| f.path.as_str()).collect();
                return Err(Error::Invalid(format!(
                    "parameter {p:?} is not in the scene's fit section (it has: {})",
                    known.join(", ")
                )));
            }
        }
        let mut layout = ParamLayout {
            entries: Vec::new(),
            bounds: Vec::new(),
            names: Vec::new(),
        };
        for f in scene.fit.iter().filter(|f| paths.contains(&f.path)) {
            let offset = layout.bounds.len();
            layout.entries.push((f.path.clone(), f.target, offset));
            let suffix: &[&str] = match f.target.len() {
                1 => &[""],
                _ if f.target.is_vector() => &[".x", ".y", ".z"],
                _ => &[".r", ".g", ".b"],
            };
            for k in 0..f.target.len() {
                layout.bounds.push((f.min[k], f.max[k]));
                layout.names.push(format!("{}{}", f.path, suffix[k]));
            }
        }
        Ok(layout)
    }

    /// All of the scene's fit parameters.
    pub fn all(scene: &Scene) -> ParamLayout {
        let paths: Vec<String> = scene.fit.iter().map(|f| f.path.clone()).collect();
        ParamLayout::new(scene, &paths).expect("the scene's own paths are valid")
    }

    pub fn dim(&self) -> usize {
        self.bounds.len()
    }

    /// Write the parameter vector `x` into `scene`.
    pub fn apply(&self, scene: &mut Scene, x: &[f64]) {
        for (_, target, offset) in &self.entries {
            target.set(scene, &x[*offset..*offset + target.len()]);
        }
    }

    /// Read the current values from `scene`.
    pub fn read(&self, scene: &Scene) -> Vec<f64> {
        let mut x = Vec::with_capacity(self.dim());
        for (_, target, _) in &self.entries {
            x.extend(target.get(scene));
        }
        x
    }
}
