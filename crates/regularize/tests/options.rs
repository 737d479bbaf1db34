//! `Overrides::resolve` against the mapping the three front ends each wrote before it
//! (kept here as the reference, over the former flat parameters), read the way the former
//! pipeline read them (`typed`): equal `Params`, field for field, for every preset and a set
//! of option combinations.

use voxreg_digisurf::RegionMap;
use voxreg_regularize::{
    Clamp, ClampOverride, Clamped, EnergyParams, Estimator, Fidelity, InputFacts, Mode, NormalsParams,
    Overrides, Params, Preset, Recentring, Regions, SolverChoice, SolverParams, SweepsParams,
};

/// The former flat parameters: 17 fields, some read only when others are set.
#[derive(Clone, Debug)]
struct Former {
    regions: RegionMap,
    normals: NormalsParams,
    energy: EnergyParams,
    refine: usize,
    intermediate_tolerance: f64,
    refine_radius: f64,
    feature_angle_deg: f64,
    preserve_size: bool,
    recentre_sigma: f64,
    crease_alignment: f64,
    crease_angle_deg: f64,
    crease_dilation: usize,
    sheet_thickness: f64,
    texture_aware: bool,
    junction_fairness: bool,
    solver: SolverParams,
    fold_free: bool,
}

impl Former {
    fn default() -> Self {
        Former {
            regions: RegionMap::per_label(),
            normals: NormalsParams::default(),
            energy: Params::ENERGY,
            refine: 3,
            intermediate_tolerance: 2.0,
            refine_radius: 3.0,
            feature_angle_deg: 30.0,
            preserve_size: true,
            recentre_sigma: 3.0,
            crease_alignment: 0.015,
            crease_angle_deg: 20.0,
            crease_dilation: 1,
            sheet_thickness: 2.5,
            texture_aware: false,
            junction_fairness: true,
            solver: SolverParams::default(),
            fold_free: false,
        }
    }

    fn papers() -> Self {
        Former {
            energy: EnergyParams::default(),
            refine: 0,
            preserve_size: false,
            crease_alignment: 1.0,
            ..Former::default()
        }
    }

    fn voxel_art() -> Self {
        let mut solver = SolverParams::default().clamped(Some(0.01));
        solver.bounded.thin_depth = Some(0.3);
        let normals = NormalsParams { radius_voxels: Some(2.0), ..Default::default() };
        Former {
            regions: RegionMap::single_solid(),
            refine: 0,
            solver,
            fold_free: true,
            normals,
            energy: EnergyParams { gamma: 1.0, ..Params::ENERGY },
            ..Former::default()
        }
    }

    fn fast() -> Self {
        Former {
            normals: NormalsParams { estimator: Estimator::Diffused, ..Default::default() },
            refine: 0,
            refine_radius: Params::FAST_RADIUS,
            preserve_size: false,
            crease_alignment: 1.0,
            sheet_thickness: 0.0,
            solver: SolverParams {
                choice: SolverChoice::Sweeps,
                sweeps: SweepsParams { sweeps: Params::FAST_SWEEPS, ..Default::default() },
                ..Default::default()
            },
            ..Former::default()
        }
    }

    fn with_smoothness(mut self, s: f64) -> Option<Self> {
        if !(s > 0.0 && s <= 1.0) {
            return None;
        }
        let thin = self.solver.bounded.thin_depth;
        self.solver = self.solver.clamped(Some(1.0 - 0.99 * s));
        self.solver.bounded.thin_depth = thin;
        Some(self)
    }
}

/// The typed parameters of what the former pipeline read from `f`: the boxes, their thin
/// depth and the refinement when the bounded solver clamped (the intermediate tolerance
/// and the re-centring it ignored then); otherwise the refinement, the intermediate
/// tolerance and the re-centring (its sigma only when on).
fn typed(f: Former) -> Params {
    let mut p = Params {
        regions: f.regions,
        normals: f.normals,
        energy: f.energy,
        texture_aware: f.texture_aware,
        junction_fairness: f.junction_fairness,
        fold_free: f.fold_free,
        solver: f.solver,
        ..Default::default()
    };
    (p.solver.bounded.clamp, p.solver.bounded.thin_depth) = (None, None);
    let r = p.refinement_mut();
    (r.rounds, r.radius, r.feature_angle_deg, r.sheet_thickness) =
        (f.refine, f.refine_radius, f.feature_angle_deg, f.sheet_thickness);
    (r.creases.alignment, r.creases.angle_deg, r.creases.dilation) =
        (f.crease_alignment, f.crease_angle_deg, f.crease_dilation);
    let refinement = *r;
    p.mode = match f.solver.bounded.clamp.filter(|_| f.solver.choice == SolverChoice::Bounded) {
        Some(margin) => {
            let mut c = Clamped::margin(margin);
            (c.thin_depth, c.refinement) = (f.solver.bounded.thin_depth, refinement);
            Mode::Clamped(c)
        }
        None => {
            let mut fidelity = Fidelity::default();
            fidelity.refinement = refinement;
            fidelity.intermediate_tolerance = f.intermediate_tolerance;
            fidelity.recentring = f.preserve_size.then(|| {
                let mut r = Recentring::default();
                r.sigma = f.recentre_sigma;
                r
            });
            Mode::Fidelity(fidelity)
        }
    };
    p
}

/// The command line's former translation of its options (`RegularizeArgs::params`).
fn reference(preset: Preset, o: &Overrides) -> Option<Former> {
    let mut p = match preset {
        Preset::Default => Former::default(),
        Preset::Papers => Former::papers(),
        Preset::VoxelArt => Former::voxel_art(),
        Preset::Fast => Former::fast(),
    };
    if let Some(Regions::Spec(s)) = &o.regions {
        p.regions = match s.as_str() {
            "label" => RegionMap::per_label(),
            "solid" => RegionMap::single_solid(),
            spec => RegionMap::parse(spec).ok()?,
        };
    }
    if let Some(a) = o.alpha {
        p.energy.alpha = a;
    }
    if let Some(b) = o.beta {
        p.energy.beta = b;
    }
    if let Some(g) = o.gamma {
        p.energy.gamma = g;
    }
    if let Some(n) = o.normals {
        p.normals.estimator = n;
    }
    p.normals.radius = o.radius.or(p.normals.radius);
    if let Some(k) = o.sharpen {
        p.normals.at.sharpen_iterations = k;
    }
    if let Some(t) = o.sharpen_threshold {
        p.normals.at.sharpen_threshold = t;
    }
    if let Some(k) = o.refine {
        p.refine = k;
    }
    if let Some(f) = o.intermediate_tolerance {
        p.intermediate_tolerance = f;
    }
    if o.preserve_size == Some(false) {
        p.preserve_size = false;
    }
    p.texture_aware |= o.texture_aware == Some(true);
    if let Some(t) = o.tolerance {
        p.solver = p.solver.with_tolerance(t);
    }
    if let Some(s) = o.smoothness {
        p = p.with_smoothness(s)?;
    }
    let clamp = match o.clamp {
        Some(Clamp::Margin(eps)) => ClampOverride::Eps(eps),
        Some(Clamp::On) => ClampOverride::Eps(0.01),
        Some(Clamp::Off) => ClampOverride::Off,
        None => ClampOverride::Keep,
    };
    p.solver = p.solver.overridden(o.solver, clamp).ok()?;
    Some(p)
}

#[test]
fn the_former_presets_read_as_the_typed_ones() {
    assert_eq!(typed(Former::default()), Params::default());
    assert_eq!(typed(Former::papers()), Params::papers());
    assert_eq!(typed(Former::voxel_art()), Params::voxel_art());
}

/// Option combinations: each field alone, and mixtures.
fn combinations() -> Vec<Overrides> {
    let mut all = vec![Overrides::default()];
    let mut one = |f: &dyn Fn(&mut Overrides)| {
        let mut o = Overrides::default();
        f(&mut o);
        all.push(o);
    };
    one(&|o| o.regions = Some(Regions::Spec("solid".into())));
    one(&|o| o.regions = Some(Regions::Spec("label".into())));
    one(&|o| o.regions = Some(Regions::Spec("1,2;3".into())));
    for n in Estimator::ALL {
        one(&|o| o.normals = Some(n));
    }
    one(&|o| o.radius = Some(2.5));
    one(&|o| o.sharpen = Some(0));
    one(&|o| o.sharpen_threshold = Some(0.3));
    one(&|o| o.alpha = Some(0.02));
    one(&|o| o.beta = Some(0.5));
    one(&|o| o.gamma = Some(0.0));
    for s in SolverChoice::ALL {
        one(&|o| o.solver = Some(s));
    }
    for c in [Clamp::On, Clamp::Off, Clamp::Margin(0.2)] {
        one(&|o| o.clamp = Some(c));
        one(&|o| {
            o.clamp = Some(c);
            o.solver = Some(SolverChoice::Bounded)
        });
        one(&|o| {
            o.clamp = Some(c);
            o.solver = Some(SolverChoice::Auto)
        });
    }
    one(&|o| o.smoothness = Some(0.4));
    one(&|o| {
        o.smoothness = Some(1.0);
        o.solver = Some(SolverChoice::Bounded)
    });
    one(&|o| o.tolerance = Some(1e-4));
    one(&|o| o.refine = Some(0));
    one(&|o| o.refine = Some(5));
    one(&|o| o.intermediate_tolerance = Some(3.0));
    one(&|o| o.preserve_size = Some(false));
    one(&|o| {
        o.preserve_size = Some(false);
        o.clamp = Some(Clamp::On)
    });
    one(&|o| {
        o.intermediate_tolerance = Some(3.0);
        o.refine = Some(2);
        o.clamp = Some(Clamp::Margin(0.2))
    });
    one(&|o| {
        o.refine = Some(2);
        o.clamp = Some(Clamp::Off)
    });
    one(&|o| o.texture_aware = Some(true));
    one(&|o| {
        o.alpha = Some(0.02);
        o.normals = Some(Estimator::Convolved);
        o.radius = Some(2.5);
        o.refine = Some(1);
        o.solver = Some(SolverChoice::Cg);
        o.tolerance = Some(1e-4);
        o.preserve_size = Some(false);
        o.regions = Some(Regions::Spec("solid".into()))
    });
    one(&|o| {
        o.normals = Some(Estimator::At);
        o.sharpen = Some(3);
        o.sharpen_threshold = Some(0.5);
        o.smoothness = Some(0.3);
        o.tolerance = Some(1e-2);
        o.texture_aware = Some(true)
    });
    all
}

#[test]
fn resolved_overrides_equal_the_former_mapping_for_every_preset() {
    let mut checked = 0;
    for preset in Preset::ALL {
        for o in combinations() {
            let expected = reference(preset, &o).map(typed).filter(|p| p.validate().is_ok());
            let got = o.resolve(Some(preset), &InputFacts::default()).ok();
            assert_eq!(got, expected, "{preset} {o:?}");
            checked += usize::from(got.is_some());
        }
    }
    assert!(checked > 100, "{checked}");
}

#[test]
fn the_input_picks_the_preset_when_none_is_named() {
    let o = Overrides::default();
    assert_eq!(o.resolve(None, &InputFacts::voxel_art(true)).unwrap(), Params::voxel_art());
    assert_eq!(o.resolve(None, &InputFacts::default()).unwrap(), Params::default());
}
