//! What the simplifier is asked for and what it answers: targets, options, results, errors.

use voxreg_io::QuadMesh;

/// How far one level of detail may go.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Target {
    /// Stop once the triangles left are at most this fraction of the input's triangles
    /// (a quad counts two): about the fraction of faces left once the triangles are paired
    /// into quads again. `None`: as far as `max_error` allows.
    pub ratio: Option<f64>,
    /// The largest distance allowed from any input vertex to the output faces, in the
    /// positions' units. Collapses that would break it are refused, so the ratio may not
    /// be reached.
    pub max_error: f64,
}

/// How collapses are judged and faces rebuilt.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Options {
    /// A collapse may turn no triangle's normal by more than this angle, in degrees.
    pub max_normal_change_deg: f64,
    /// A collapse may make no triangle of quality (`4 sqrt(3) area / sum of squared edge
    /// lengths`, 1 for an equilateral one) below this bound, unless it was lower already.
    pub min_triangle_quality: f64,
    /// Refuse collapses whose new triangles intersect a triangle they share no vertex
    /// with (exact tests against a grid of the triangles).
    pub check_intersections: bool,
    /// Pair the triangles into quads where a good pair exists, after flipping edges inside
    /// patches where that lets more triangles pair (else no flips, and the output is
    /// triangles only, written as quads repeating their last vertex).
    pub quads: bool,
    /// A pair of triangles makes a quad only if the angle between their normals is at
    /// most this, in degrees.
    pub max_quad_dihedral_deg: f64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            max_normal_change_deg: 40.0,
            min_triangle_quality: 0.1,
            check_intersections: true,
            quads: true,
            max_quad_dihedral_deg: 45.0,
        }
    }
}

/// A simplified mesh and what was done.
#[derive(Clone, Debug)]
pub struct Simplified {
    /// The mesh: quads, and triangles as quads repeating their last vertex; the input's
    /// labels, groups (same names, same order), materials and label names.
    pub mesh: QuadMesh,
    /// Counts and the distance reached.
    pub stats: Stats,
}

/// What a simplification did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Stats {
    /// Faces of the input.
    pub input_faces: usize,
    /// Triangles of the input (a quad counts two).
    pub input_triangles: usize,
    /// Triangles left after the collapses.
    pub triangles_left: usize,
    /// Faces of the output.
    pub faces: usize,
    /// Output faces that are quads.
    pub quads: usize,
    /// The largest distance of an input vertex to the output face that answers for it:
    /// every input vertex lies at most this far from the output.
    pub error_bound: f64,
    /// Vertices that never move (line end points, meeting points of lines, pinches).
    pub corners: usize,
    /// Vertices on one feature line.
    pub line_vertices: usize,
}

/// What a simplification reports as it goes (for progress bars): the level being made,
/// its stage, and how far that stage is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Progress {
    /// The level being made, from 0 (the index of its target).
    pub level: usize,
    /// How many levels the run makes.
    pub levels: usize,
    /// The stage of that level.
    pub stage: Stage,
    /// How far the stage is, from 0 to 1. For the collapses: the share of the triangles
    /// to remove that are removed (for a target without a ratio, of all the triangles, so
    /// the stage may end below 1 before its last report of 1).
    pub fraction: f64,
}

impl Progress {
    /// The share of the whole run done, from 0 to 1, for a single progress bar: the setup
    /// counts a tenth, each level an equal share of the rest (its collapses 70%, the flips
    /// and the pairing 15% each). Never decreases from one report to the next.
    pub fn overall(&self) -> f64 {
        let (start, width) = match self.stage {
            Stage::Setup => return 0.1 * self.fraction,
            Stage::Collapses => (0.0, 0.7),
            Stage::Flips => (0.7, 0.15),
            Stage::Pairing => (0.85, 0.15),
        };
        let share = 0.9 / self.levels.max(1) as f64;
        (0.1 + share * (self.level as f64 + start + width * self.fraction)).min(1.0)
    }
}

/// The stages of a simplification, in the order they run (the setup once, the others
/// once per level).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Stage {
    /// Reading the mesh: its triangles, feature lines, corners, quadrics and grid.
    Setup,
    /// The edge collapses.
    Collapses,
    /// The edge flips that let more triangles pair.
    Flips,
    /// The pairing into quads and the output mesh. A level's pairing runs on another
    /// thread beside the next level's collapses: its report at 0 marks the hand-off, and
    /// only the last level reports it done.
    Pairing,
}

impl Stage {
    /// A short lower-case name: `setup`, `collapses`, `flips`, `pairing`.
    pub fn label(self) -> &'static str {
        match self {
            Stage::Setup => "setup",
            Stage::Collapses => "collapses",
            Stage::Flips => "flips",
            Stage::Pairing => "pairing",
        }
    }
}

/// Why a mesh cannot be simplified.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SimplifyError {
    /// The mesh is inconsistent.
    #[error("invalid mesh: {0}")]
    InvalidMesh(String),
    /// The targets are out of range or not nested.
    #[error("invalid simplification target: {0}")]
    InvalidTarget(String),
    /// The caller raised the run's [`Interrupt`](crate::Interrupt).
    #[error("interrupted")]
    Interrupted,
}

/// `Err(Interrupted)` once `interrupt` is raised: the shared flag's own check, in this
/// crate's error.
pub(crate) fn check(interrupt: &crate::Interrupt) -> Result<(), SimplifyError> {
    interrupt.check().map_err(|_| SimplifyError::Interrupted)
}
