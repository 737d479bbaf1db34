//! The keyword arguments of `voxreg.regularize` onto the library's `Params`, as the CLI maps
//! its options: a preset, then every argument given applied over it (the solver and boxes
//! by the library's `SolverParams::overridden`).

use voxreg_digisurf::RegionMap;
use voxreg_regularize::{ClampOverride, Estimator, OverrideError, Params, SolverChoice};

use crate::error::{Error, Result};

/// `regions=`: the preset's, every label its own region, one solid, or label groups.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Regions {
    Label,
    Solid,
    /// A spec such as `"1,2,3;7"`, as the CLI's `--regions`.
    Spec(String),
    Groups(Vec<Vec<u32>>),
}

/// `clamp=`: `True` (0.01 voxel), `False` (no boxes, even for the voxel-art preset), or an
/// epsilon in voxels.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) enum Clamp {
    Off,
    Eps(f64),
}

/// Every argument of `voxreg.regularize` that shapes `Params`; `None` keeps the preset's.
#[derive(Clone, Debug, Default)]
pub(crate) struct Options {
    pub(crate) preset: String,
    pub(crate) regions: Option<Regions>,
    pub(crate) normals: Option<String>,
    pub(crate) radius: Option<f64>,
    pub(crate) alpha: Option<f64>,
    pub(crate) beta: Option<f64>,
    pub(crate) gamma: Option<f64>,
    pub(crate) refine: Option<i64>,
    pub(crate) preserve_size: Option<bool>,
    pub(crate) texture_aware: Option<bool>,
    pub(crate) solver: Option<String>,
    pub(crate) clamp: Option<Clamp>,
    pub(crate) smoothness: Option<f64>,
    pub(crate) tolerance: Option<f64>,
}

fn positive(name: &str, x: Option<f64>) -> Result<Option<f64>> {
    match x {
        Some(x) if !(x.is_finite() && x > 0.0) => {
            Err(Error::parameter(format!("{name} must be finite and positive, got {x}")))
        }
        _ => Ok(x),
    }
}

fn non_negative(name: &str, x: Option<f64>) -> Result<Option<f64>> {
    match x {
        Some(x) if !(x.is_finite() && x >= 0.0) => {
            Err(Error::parameter(format!("{name} must be finite and non-negative, got {x}")))
        }
        _ => Ok(x),
    }
}

fn one_of<T: Copy>(name: &str, value: &str, choices: &[(&str, T)]) -> Result<T> {
    choices.iter().find(|(n, _)| *n == value).map(|&(_, t)| t).ok_or_else(|| {
        let names: Vec<String> = choices.iter().map(|(n, _)| format!("'{n}'")).collect();
        Error::parameter(format!("{name} must be one of {}, got '{value}'", names.join(", ")))
    })
}

impl Options {
    /// The region map of `regions=`, or `None` for the preset's.
    fn region_map(&self) -> Result<Option<RegionMap>> {
        Ok(match &self.regions {
            None => None,
            Some(Regions::Label) => Some(RegionMap::per_label()),
            Some(Regions::Solid) => Some(RegionMap::single_solid()),
            Some(Regions::Spec(spec)) => {
                Some(RegionMap::parse(spec).map_err(|e| Error::parameter(format!("regions '{spec}': {e}")))?)
            }
            Some(Regions::Groups(groups)) => Some(
                RegionMap::from_groups(groups.clone())
                    .map_err(|e| Error::parameter(format!("regions {groups:?}: {e}")))?,
            ),
        })
    }

    /// The library's parameters, validated.
    pub(crate) fn params(&self) -> Result<Params> {
        let mut p = one_of(
            "preset",
            &self.preset,
            &[
                ("default", Params::default as fn() -> Params),
                ("papers", Params::papers),
                ("voxel_art", Params::voxel_art),
            ],
        )?();
        if let Some(map) = self.region_map()? {
            p.regions = map;
        }
        if let Some(a) = positive("alpha", self.alpha)? {
            p.energy.alpha = a;
        }
        if let Some(b) = non_negative("beta", self.beta)? {
            p.energy.beta = b;
        }
        if let Some(g) = non_negative("gamma", self.gamma)? {
            p.energy.gamma = g;
        }
        if let Some(n) = &self.normals {
            p.normals.estimator = one_of(
                "normals",
                n,
                &[
                    ("trivial", Estimator::Trivial),
                    ("convolved", Estimator::Convolved),
                    ("ii", Estimator::Ii),
                    ("at", Estimator::At),
                ],
            )?;
        }
        p.normals.radius = positive("radius", self.radius)?.or(p.normals.radius);
        if let Some(k) = self.refine {
            p.refine = usize::try_from(k)
                .map_err(|_| Error::parameter(format!("refine must be a non-negative integer, got {k}")))?;
        }
        if let Some(keep) = self.preserve_size {
            p.preserve_size = keep;
        }
        if let Some(t) = self.texture_aware {
            p.texture_aware = t;
        }
        if let Some(t) = positive("tolerance", self.tolerance)? {
            p.solver = p.solver.with_tolerance(t);
        }
        if let Some(s) = self.smoothness {
            if self.clamp.is_some() {
                return Err(Error::parameter(
                    "smoothness and clamp exclude each other (smoothness sets the boxes)",
                ));
            }
            p = p
                .with_smoothness(s)
                .map_err(|_| Error::parameter(format!("smoothness must be in (0, 1], got {s}")))?;
        }
        let solver = match &self.solver {
            None => None,
            Some(s) => Some(one_of(
                "solver",
                s,
                &[
                    ("auto", SolverChoice::Auto),
                    ("direct", SolverChoice::Direct),
                    ("cg", SolverChoice::Cg),
                    ("bounded", SolverChoice::Bounded),
                    ("gd", SolverChoice::Bounded),
                ],
            )?),
        };
        let clamp = match self.clamp {
            None => ClampOverride::Keep,
            Some(Clamp::Off) => ClampOverride::Off,
            Some(Clamp::Eps(eps)) => ClampOverride::Eps(eps),
        };
        p.solver = p.solver.overridden(solver, clamp).map_err(|e| match e {
            OverrideError::ClampNeedsBoundedSolver => {
                Error::parameter("clamp needs the bounded solver (solver='bounded' or 'auto')")
            }
            OverrideError::ClampOutOfRange(eps) => {
                Error::parameter(format!("clamp: EPS must be in (0, 1) voxel, got {eps}"))
            }
        })?;
        p.validate().map_err(|e| Error::regularize("", &e))?;
        Ok(p)
    }
}
