//! The finish stage: the fold-free post-condition and the energies before and after.

use std::borrow::Cow;

use glam::DVec3;
use voxreg_digisurf::{DigitalSurface, VertexData};
use voxreg_normals::NormalField;

use crate::energy::Energy;
use crate::error::RegularizeError;
use crate::params::Params;
use crate::report::EnergyReport;
use crate::weights::Weights;

/// Finishes a run: unfolds `positions` where [`Params::fold_free`] asks, then measures the
/// energy of the last round (its normals `field` and `targets`, with `weights` but without
/// the creases') at the lattice positions and at the result.
pub(crate) fn finish(
    surface: &DigitalSurface,
    params: &Params,
    positions: &mut VertexData<DVec3>,
    field: &NormalField,
    targets: &VertexData<DVec3>,
    weights: Option<&Weights>,
) -> Result<EnergyReport, RegularizeError> {
    // The lattice positions: the targets themselves where no round re-centred them.
    let staircase = if params.refinement().rounds == 0 {
        Cow::Borrowed(targets.as_slice())
    } else {
        Cow::Owned(surface.positions().into_vec())
    };
    if params.fold_free {
        crate::unfold::unfold(surface, &staircase, positions);
    }
    let energy = Energy::new(surface, field, targets, params.energy)?;
    let energy = match weights {
        Some(w) => energy.with_weights(w)?,
        None => energy,
    };
    let (before, after) = (energy.terms(&staircase), energy.terms(positions));
    drop(staircase);
    if !(before.total.is_finite() && after.total.is_finite()) {
        return Err(RegularizeError::NotFinite(format!(
            "the energy is not finite ({} -> {}): the weights or the spacing are out of range",
            before.total, after.total
        )));
    }
    Ok(EnergyReport { before, after })
}
