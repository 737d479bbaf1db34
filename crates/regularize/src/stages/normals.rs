//! The normals stage: the initial normal field, given, estimated, or kept from the last
//! run.

use voxreg_digisurf::DigitalSurface;
use voxreg_normals::{AtInfo, FeatureField, Interrupt, NormalField, QuadGraph};

use crate::error::RegularizeError;
use crate::params::{EstimatedNormals, Estimator, NormalsParams};

/// The normals stage's result.
pub(crate) struct Initial {
    /// One direction per surfel.
    pub(crate) field: NormalField,
    /// The Ambrosio-Tortorelli feature field, for its estimator.
    pub(crate) features: Option<FeatureField>,
    /// The Ambrosio-Tortorelli iterations and timings, for its estimator.
    pub(crate) at_info: Option<AtInfo>,
    /// The estimator's name, or `"given"`.
    pub(crate) estimator: &'static str,
}

/// The initial field: `given` (one direction per surfel), else `params`' estimate,
/// reused from `cache` where it was made with the same parameters, and left there for the
/// next runs when `keep`. The diffused estimate uses the surfel graph in `graph`, built
/// there if it is not, for the sweeps solver's re-estimates.
pub(crate) fn initial_normals(
    surface: &DigitalSurface,
    params: &NormalsParams,
    given: Option<&NormalField>,
    cache: &mut Option<(NormalsParams, EstimatedNormals)>,
    keep: bool,
    graph: &mut Option<QuadGraph>,
    interrupt: &Interrupt,
) -> Result<Initial, RegularizeError> {
    if let Some(field) = given {
        if field.len() != surface.num_surfels() {
            return Err(RegularizeError::SizeMismatch(format!(
                "{} normals for {} surfels",
                field.len(),
                surface.num_surfels()
            )));
        }
        return Ok(Initial { field: field.clone(), features: None, at_info: None, estimator: "given" });
    }
    if cache.as_ref().is_none_or(|(p, _)| p != params) {
        let estimated = if params.estimator == Estimator::Diffused {
            let g = graph.get_or_insert_with(|| QuadGraph::new(surface));
            params.diffused_on(surface, g, interrupt)?
        } else {
            params.estimate_interruptible(surface, interrupt)?
        };
        *cache = Some((params.clone(), estimated));
    }
    let estimator = params.estimator.name();
    Ok(if keep {
        let (_, n) = cache.as_ref().expect("estimated above");
        Initial {
            field: n.field.clone(),
            features: n.features.clone(),
            at_info: n.at_info.clone(),
            estimator,
        }
    } else {
        let (_, n) = cache.take().expect("estimated above");
        Initial { field: n.field, features: n.features, at_info: n.at_info, estimator }
    })
}
