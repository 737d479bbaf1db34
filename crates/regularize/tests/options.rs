//! `Overrides::resolve` against the mapping the three front ends each wrote before it
//! (kept here as the reference): equal `Params`, field for field, for every preset and a
//! set of option combinations.

use voxreg_digisurf::RegionMap;
use voxreg_regularize::{
    Clamp, ClampOverride, Estimator, InputFacts, Overrides, Params, Preset, Regions, SolverChoice,
};

/// The command line's former translation of its options (`RegularizeArgs::params`).
fn reference(preset: Preset, o: &Overrides) -> Option<Params> {
    let mut p = match preset {
        Preset::Default => Params::default(),
        Preset::Papers => Params::papers(),
        Preset::VoxelArt => Params::voxel_art(),
        Preset::Fast => Params::fast(),
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
        p = p.with_smoothness(s).ok()?;
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
            let expected = reference(preset, &o).filter(|p| p.validate().is_ok());
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
