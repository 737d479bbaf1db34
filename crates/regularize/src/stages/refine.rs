//! The refine stage: the normals re-estimated from the last solve's quads
//! ([`voxreg_normals::Refined`]), relaxed where they swing back, thin sheets holding their
//! first round's, and the targets re-centred ([`super::recentre`]).

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use voxreg_digisurf::{DigitalSurface, Surfel, VertexData};
use voxreg_normals::{
    anisotropic_fit_weight, Diffused, Interrupt, NormalField, ProbeHints, QuadGraph, Refined,
};

use crate::error::RegularizeError;
use crate::faces::FaceIndex;
use crate::mode::Refinement;

use super::recentre::RecentringInputs;

/// The refine stage's state across the rounds of one run.
pub(crate) struct Refine<'a> {
    surface: &'a DigitalSurface,
    refinement: Refinement,
    /// The re-centring's inputs and its sigma, where the run re-centres.
    recentring: Option<(&'a RecentringInputs, f64)>,
    /// The sagitta lift's blend with the anisotropy, like the refinement's fit (0 on
    /// cubic voxels).
    lift_weight: f64,
    /// The thin sheets' quads, with the normals they keep from the first round on and
    /// their shares.
    held: Vec<(u32, DVec3, f64)>,
    /// Each quad's last change of normal, for the relaxation of the next round's.
    change: Option<Vec<Vec3>>,
    /// Which quads' wide junction discs the last round found in use (see `Refined`).
    hints: ProbeHints,
}

impl<'a> Refine<'a> {
    /// The stage on `surface`, from the initial field `start` (which finds the thin
    /// sheets, when there are rounds).
    pub(crate) fn new(
        surface: &'a DigitalSurface,
        start: &NormalField,
        refinement: Refinement,
        recentring: Option<(&'a RecentringInputs, f64)>,
    ) -> Self {
        let held = if refinement.rounds > 0 {
            thin_sheets(surface, start, refinement.sheet_thickness)
                .into_iter()
                .map(|(s, share)| (s, DVec3::ZERO, share))
                .collect()
        } else {
            Vec::new()
        };
        Refine {
            surface,
            refinement,
            recentring,
            lift_weight: anisotropic_fit_weight(surface.spacing()),
            held,
            change: None,
            hints: ProbeHints::default(),
        }
    }

    /// Round `round` (from 1): `field` refined from the last solve's `positions`, and
    /// `targets` re-centred where the run re-centres.
    pub(crate) fn round(
        &mut self,
        round: usize,
        positions: &VertexData<DVec3>,
        field: &mut NormalField,
        targets: &mut VertexData<DVec3>,
        interrupt: &Interrupt,
    ) -> Result<(), RegularizeError> {
        let surface = self.surface;
        let estimate = Refined {
            positions,
            previous: field,
            radius: self.refinement.radius,
            feature_angle_deg: self.refinement.feature_angle_deg,
        }
        .estimate_with_hints(surface, interrupt, &mut self.hints)?;
        // Thin sheets keep the first round's normals.
        let estimate = if round == 1 {
            self.held.iter_mut().for_each(|h| h.1 = estimate.as_slice()[h.0 as usize]);
            estimate
        } else {
            hold_thin_sheets(estimate, &self.held)
        };
        *field = relaxed_normals(field, estimate, &mut self.change);
        if let Some((inputs, sigma)) = self.recentring {
            let drift = inputs.drift(surface, positions, field, self.lift_weight, sigma, interrupt)?;
            targets.iter_mut().zip(&drift).for_each(|(t, d)| *t -= *d);
        }
        Ok(())
    }
}

impl Refine<'_> {
    /// A round of the fast pipeline ([`crate::Params::fast`]): `field` re-estimated from
    /// the last batch of sweeps' `positions` by diffusing the quads' vector areas over the
    /// refinement's radius ([`Diffused`]) on the sweeps solver's surfel `graph`; no thin
    /// sheets, relaxation or re-centring.
    pub(crate) fn diffused(
        &self,
        positions: &VertexData<DVec3>,
        field: &mut NormalField,
        graph: &QuadGraph,
        interrupt: &Interrupt,
    ) -> Result<(), RegularizeError> {
        Diffused::update_on(positions, self.refinement.radius, self.surface, graph, field, interrupt)?;
        Ok(())
    }
}

/// The scale below which a quad's normal changes are not treated as an oscillation by
/// [`relaxed_normals`], squared: 1e-4 (a hundredth of a radian, about 0.6 degree).
const OSCILLATION_SCALE2: f64 = 1e-4;

/// The refined normals of a round, relaxed where they swing back: each quad moves from
/// its normal `n` of the last round by `t d` instead of the whole change
/// `d = estimate - n`, with `t = 1 / (1 + c)` and
/// `c = max(0, -d . p) / (|p|^2 + s^2)`, where `p` is the change the quad took in the
/// round before (`previous`, updated here to the change taken now) and `s` a hundredth of
/// a radian. A quad whose normal keeps turning the same way, or barely moved, takes the
/// estimate (`c = 0`); one that undoes its last change (`d = -p`, an oscillation between
/// two normals) takes about half of it, the midpoint that the iteration would otherwise
/// circle around. `t` is a continuous function of the normals, so a small change of the
/// positions changes the result little (chunks must agree with the whole volume).
///
/// Why: on thin sheets of real segmentations the rounds do not settle on their own: some
/// quads' normals alternate between two directions, and the alternation amplifies a
/// difference of the positions (a solver tolerance, a chunk's cut) round after round.
pub(crate) fn relaxed_normals(
    field: &NormalField,
    estimate: NormalField,
    previous: &mut Option<Vec<Vec3>>,
) -> NormalField {
    let (n, e) = (field.as_slice(), estimate.as_slice());
    let change =
        |relaxed: &[DVec3]| Some(relaxed.par_iter().zip(n).map(|(r, n)| (*r - *n).as_vec3()).collect());
    let relaxed: Vec<DVec3> = match previous.as_deref() {
        None => {
            *previous = change(e);
            return estimate;
        }
        Some(p) => n
            .par_iter()
            .zip(e)
            .zip(p)
            .map(|((n, e), p)| {
                let (d, p) = (*e - *n, p.as_dvec3());
                let c = (-d.dot(p)).max(0.0) / (p.length_squared() + OSCILLATION_SCALE2);
                let m = (*n + d / (1.0 + c)).normalize_or_zero();
                if m == DVec3::ZERO {
                    *e
                } else {
                    m
                }
            })
            .collect(),
    };
    *previous = change(&relaxed);
    NormalField::new(relaxed)
}

/// Full width, in voxels of the finest spacing, of the thin-sheet rule's ramp (see
/// [`thin_sheets`]): a quad's share falls from 1 at `thickness - 0.5` to 0 at
/// `thickness + 0.5`.
const SHEET_RAMP: f64 = 1.0;

/// The angles, in degrees, between a sheet's two sides (their outward normals, one
/// reversed) within which they count as parallel in full and past which not at all
/// (see [`thin_sheets`]).
const SHEET_PARALLEL_DEG: [f64; 2] = [30.0, 50.0];

/// The quads of thin sheets, as `(surfel, share)` with `share` in `(0, 1]`: for each quad
/// and each of its two regions, the distance from the quad's centre through that region
/// along `field`'s normal to the region's other side (marched voxel by voxel, in voxels of
/// the finest spacing), where that side faces the opposite way (its outward normal in
/// `field` within [`SHEET_PARALLEL_DEG`] of the march). The share is 1 for a sheet
/// thinner than `thickness - 0.5`, 0 from `thickness + 0.5` on, linear between, and
/// weighed by how parallel the sides are; the thinner region counts. A quad whose
/// normal in `field` does not enter a region through the quad skips that region.
///
/// Why: a region one or two voxels thick between two others (a membrane between two
/// compartments of a segmentation) is a long sheet whose tilt only the weak attachment
/// holds; refined normals read that tilt back and the next solve amplifies it, so the
/// rounds do not settle there and a difference of thousandths of a voxel (a solver's
/// tolerance, a chunk's cut) grows to tenths. Measured on the initial field (from the
/// voxels alone), the rule does not depend on the positions; the wedges at the rim of a
/// thick region (sides not parallel) are not sheets.
pub(crate) fn thin_sheets(surface: &DigitalSurface, field: &NormalField, thickness: f64) -> Vec<(u32, f64)> {
    if thickness <= 0.0 {
        return Vec::new();
    }
    let reach = thickness + 0.5 * SHEET_RAMP;
    let dims = surface.dims().map(|d| d as i64);
    let faces = FaceIndex::new(surface);
    let h = surface.spacing();
    let unit = h.min_element();
    let [par_one, par_zero] = SHEET_PARALLEL_DEG.map(|a| a.to_radians().cos());
    let normals = field.as_slice();
    // From quad `s` into its region `side` along `dir`: the distance to the region's far
    // side and how parallel that side is; `None` past `reach` or out of the domain.
    let march = |s: &Surfel, side: usize, dir: DVec3| -> Option<(f64, f64)> {
        let a = s.axis as usize;
        let mut p = DVec3::from_array(s.cell.map(|c| c as f64 + 0.5));
        p[a] = s.cell[a] as f64;
        // Lattice steps per voxel of the finest spacing.
        let u = dir * unit / h;
        let mut v = s.voxels()[side];
        let mut next = [f64::INFINITY; 3];
        let mut delta = [f64::INFINITY; 3];
        for k in 0..3 {
            if u[k] != 0.0 {
                let bound = if u[k] > 0.0 { (v[k] + 1) as f64 } else { v[k] as f64 };
                next[k] = ((bound - p[k]) / u[k]).max(0.0);
                delta[k] = 1.0 / u[k].abs();
            }
        }
        // The quad's own face is behind the start.
        next[a] = delta[a];
        loop {
            let k = (0..3).min_by(|&i, &j| next[i].total_cmp(&next[j])).expect("three axes");
            let t = next[k];
            if t >= reach {
                return None;
            }
            let mut cell = v;
            if u[k] > 0.0 {
                cell[k] += 1;
            }
            if let Some(g) = faces.get(k, cell) {
                let far = &surface.surfels()[g as usize];
                let n = normals[g as usize];
                let outward = if far.regions[0] == s.regions[side] { n } else { -n };
                let parallel = ((dir.dot(outward) - par_zero) / (par_one - par_zero)).clamp(0.0, 1.0);
                return Some((t, parallel));
            }
            v[k] += if u[k] > 0.0 { 1 } else { -1 };
            if v[k] < -1 || v[k] > dims[k] {
                return None;
            }
            next[k] += delta[k];
        }
    };
    surface
        .surfels()
        .par_iter()
        .zip(normals.par_iter())
        .enumerate()
        .filter_map(|(i, (s, n))| {
            let oriented = s.normal();
            let share = (0..2)
                .filter_map(|side| {
                    // Into the inner voxel against the normal, into the outer one along it.
                    let dir = if side == 0 { -*n } else { *n };
                    let entering = if side == 0 { -dir.dot(oriented) } else { dir.dot(oriented) };
                    if entering <= 1e-6 {
                        return None;
                    }
                    let (t, parallel) = march(s, side, dir)?;
                    let thin = ((thickness + 0.5 * SHEET_RAMP - t) / SHEET_RAMP).clamp(0.0, 1.0);
                    Some(thin * parallel)
                })
                .fold(0.0, f64::max);
            (share > 0.0).then_some((i as u32, share))
        })
        .collect()
}

/// `estimate` moved towards the normals `held` (one per quad of a thin sheet, with its
/// share from [`thin_sheets`]): by each quad's share, all the way at share 1.
pub(crate) fn hold_thin_sheets(estimate: NormalField, held: &[(u32, DVec3, f64)]) -> NormalField {
    if held.is_empty() {
        return estimate;
    }
    let mut normals = estimate.as_slice().to_vec();
    for &(s, n, share) in held {
        let e = &mut normals[s as usize];
        let m = (share * n + (1.0 - share) * *e).normalize_or_zero();
        *e = if m == DVec3::ZERO { n } else { m };
    }
    NormalField::new(normals)
}

#[cfg(test)]
mod tests {
    use voxreg_normals::NormalEstimator;
    use voxreg_testkit::{digitize, Sphere};

    use super::*;

    #[test]
    fn relaxed_normals_halve_an_oscillation_and_keep_a_steady_turn() {
        let unit = |x: f64, y: f64| DVec3::new(x, y, 1.0).normalize();
        let n0 = NormalField::new(vec![unit(0.0, 0.0), unit(0.0, 0.0), unit(0.0, 0.0)]);
        let n1 = NormalField::new(vec![unit(0.2, 0.0), unit(0.2, 0.0), unit(1e-4, 0.0)]);
        // The first round has no previous change: the estimate as it is.
        let mut previous = None;
        let r1 = relaxed_normals(&n0, n1.clone(), &mut previous);
        assert_eq!(r1.as_slice(), n1.as_slice());
        // Then: quad 0 swings back to where it was, quad 1 keeps turning the same way,
        // quad 2 swings back by a change far below the oscillation scale.
        let e2 = NormalField::new(vec![unit(0.0, 0.0), unit(0.4, 0.0), unit(0.0, 0.0)]);
        let r2 = relaxed_normals(&r1, e2.clone(), &mut previous);
        let (r, e) = (r2.as_slice(), e2.as_slice());
        let mid = (n1.as_slice()[0] + e[0]).normalize();
        assert!(r[0].angle_between(mid) < 0.01, "{} from the midpoint", r[0].angle_between(mid));
        assert_eq!(r[1], e[1]);
        assert!(r[2].angle_between(e[2]) < 1e-6);
        for m in r {
            assert!((m.length() - 1.0).abs() < 1e-12);
        }
        // The change taken is what the next round compares with.
        let p = previous.unwrap();
        assert!((p[1].as_dvec3() - (e[1] - n1.as_slice()[1])).length() < 1e-7);
    }

    #[test]
    fn relaxed_normals_are_continuous_in_the_estimate() {
        // The estimate's change crosses from turning on (d . p > 0) to swinging back
        // (d . p < 0) at k = 0: a tiny change of the estimate moves the result by about as
        // much, not by a jump (a rule switching at d . p = 0 would jump by degrees here).
        let n = DVec3::new(0.0, 0.0, 1.0);
        let mut last = None;
        for k in -5..=5 {
            let e = DVec3::new(1e-6 * k as f64, 0.3, 1.0).normalize();
            let mut previous = Some(vec![Vec3::new(0.1, 0.0, 0.0)]);
            let r = relaxed_normals(&NormalField::new(vec![n]), NormalField::new(vec![e]), &mut previous);
            let m = r.as_slice()[0];
            if let Some(l) = last {
                assert!(m.angle_between(l) < 1e-5, "step {k}: {}", m.angle_between(l));
            }
            last = Some(m);
        }
    }

    /// A sheet of label 2, `thickness` voxels thick along z, sloping one in three along x,
    /// between label 1 below and label 3 above, in a 40 x 24 x 28 box; and its integral
    /// invariant normals.
    fn sloping_sheet(thickness: f64) -> (DigitalSurface, NormalField) {
        let volume = voxreg_digisurf::LabelVolume::from_fn([40, 24, 28], |[x, _, z]| {
            let h = z as f64 + 0.5 - 8.0 - (x as f64 + 0.5) / 3.0;
            if h < 0.0 {
                1
            } else if h < thickness {
                2
            } else {
                3
            }
        });
        let surface = DigitalSurface::from_volume(&volume).unwrap();
        let field = voxreg_normals::IntegralInvariant { radius: None }.estimate(&surface).unwrap();
        (surface, field)
    }

    /// The sheet's own quads (between labels 1 and 2 or 2 and 3), away from the box.
    fn sheet_quads(surface: &DigitalSurface) -> Vec<usize> {
        (0..surface.num_surfels())
            .filter(|&i| {
                let s = &surface.surfels()[i];
                let inside = (6..34).contains(&s.cell[0]) && (6..18).contains(&s.cell[1]);
                inside && s.labels.contains(&2) && s.labels.iter().all(|&l| l != 0)
            })
            .collect()
    }

    #[test]
    fn thin_sheets_are_the_quads_of_sheets_one_or_two_voxels_thick() {
        // Thickness along z, the shares' range on the sheet's quads.
        for (thickness, least, most) in [(1.0, 1.0, 1.0), (1.8, 0.5, 1.0), (4.0, 0.0, 0.0)] {
            let (surface, field) = sloping_sheet(thickness);
            let shares: std::collections::HashMap<u32, f64> =
                thin_sheets(&surface, &field, 2.5).into_iter().collect();
            let quads = sheet_quads(&surface);
            assert!(quads.len() > 200);
            for f in quads {
                let share = shares.get(&(f as u32)).copied().unwrap_or(0.0);
                assert!(share >= least && share <= most, "thickness {thickness}, quad {f}: {share}");
            }
        }
        // A ball is thick everywhere along its normals, the rim of a shallow cap included
        // (its two sides are not parallel); 0 turns the rule off.
        let ball = DigitalSurface::from_volume(&digitize(&Sphere { radius: 9.3 }, 1.0)).unwrap();
        let field = voxreg_normals::IntegralInvariant { radius: None }.estimate(&ball).unwrap();
        assert!(thin_sheets(&ball, &field, 2.5).is_empty());
        let (surface, field) = sloping_sheet(1.0);
        assert!(thin_sheets(&surface, &field, 0.0).is_empty());
    }

    #[test]
    fn held_normals_move_the_estimate_by_their_share() {
        let (a, b) = (DVec3::X, DVec3::Y);
        let estimate = NormalField::new(vec![a, a, a]);
        let held = hold_thin_sheets(estimate, &[(0, b, 1.0), (2, b, 0.5)]);
        let [full, none, half] = [0, 1, 2].map(|i| held.as_slice()[i]);
        assert!(full.distance(b) < 1e-15 && none.distance(a) < 1e-15);
        assert!((half.angle_between(a) - half.angle_between(b)).abs() < 1e-12 && half.angle_between(a) > 0.7);
    }

    #[test]
    fn thin_sheets_keep_the_first_rounds_normals() {
        let (surface, _) = sloping_sheet(1.0);
        let run = |refine: usize, sheet_thickness: f64| {
            let mut params = crate::Params::default();
            let refinement = params.refinement_mut();
            (refinement.rounds, refinement.sheet_thickness) = (refine, sheet_thickness);
            crate::Regularizer::new(surface.clone()).run(&params).unwrap().normals
        };
        let quads = sheet_quads(&surface);
        let turn = |a: &NormalField, b: &NormalField| {
            quads.iter().map(|&f| a.as_slice()[f].angle_between(b.as_slice()[f])).fold(0.0, f64::max)
        };
        let first = run(1, 2.5);
        assert!(turn(&first, &run(3, 2.5)) < 1e-9);
        // Refined in every round, the same quads turn on.
        let free = turn(&run(1, 0.0), &run(3, 0.0));
        assert!(free > 1e-4, "{free}");
    }
}
