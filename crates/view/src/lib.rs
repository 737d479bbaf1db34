//! `voxreg view`: a local web page that shows a voxel volume's regularized surface, the
//! solver's iterates as it converges, and re-solves it as its parameters are tuned.
//!
//! The [`Viewer`] is an HTTP server on the loopback interface (`127.0.0.1`, a free port
//! by default) serving one page and everything it loads (three.js included: no network
//! needed), and a worker thread that owns the input's
//! [`Regularizer`](voxreg_regularize::Regularizer), so that a re-solve reuses the
//! surface, the solver's symbolic analysis and unchanged normals, and starts each solve
//! round from the last run's solution
//! ([`Run::warm`](voxreg_regularize::Run::warm())). The page receives the
//! state as server-sent events (`/api/events`) and fetches positions as little-endian
//! `f32` arrays; while a solve runs, the iterates stream
//! ([`Event::iterate`](voxreg_regularize::Event::iterate)) at most every 60 ms.
//!
//! Once a run is over, the page may show a coarser level of detail of its result (a
//! quarter, a sixteenth, a sixty-fourth of the faces: the pyramid of `voxreg regularize
//! --lod 4`, simplified by [`voxreg_simplify`] with the labels, colours and partition
//! kept), chosen with `POST /api/level`: the pyramid is computed on its own thread once
//! per result, when a coarser level is first chosen, and dropped when a new run starts.
//!
//! - [`Viewer::bind`], [`Viewer::open`], [`Viewer::serve`]: listen, queue the first input
//!   ([`Loaded`]), answer requests; [`StopHandle`] stops it.
//! - [`read_volume`]: an input read as the command line reads it, a MagicaVoxel scene of
//!   models far apart as blocks ([`Volume::Blocks`]): such a scene opens, is meshed and
//!   edited within the memory of its models' boxes, not of their bounding box.
//! - [`Tuning`]: the page's parameter panel, a [`Preset`](voxreg_regularize::Preset) and
//!   the library's [`Overrides`](voxreg_regularize::Overrides), resolved into
//!   [`Params`](voxreg_regularize::Params) as the command line resolves its options, and
//!   back to that command line.
//!
//! Bad input from the page (a corrupt file, an absurd parameter) is answered with the
//! library's error message; a request that panics is answered with an error, and the
//! server keeps serving.
//!
//! **Trust.** The server answers loopback peers only, under its own host names; every
//! API request must carry the session's random token (printed in [`Viewer::url`], as
//! Jupyter does), and requests from another origin are refused, so that another local
//! user or a web page open in the same browser can neither read the session nor queue
//! work. A request body is refused (413) from its declared length before any of it is
//! read. Uploads are read from memory by the [`Loader`], never from a path their header
//! names. [`Viewer::respond_to`] answers a request held in memory (the fuzz target's way
//! in).
//!
//! # Example
//!
//! ```no_run
//! use voxreg_regularize::{Overrides, Preset};
//! use voxreg_view::{Loaded, Viewer};
//! # let volume = voxreg_digisurf::LabelVolume::from_fn([3, 3, 3], |_| 1);
//! let loaded = Loaded {
//!     name: "ball.vol".into(),
//!     volume: volume.into(),
//!     palette: None,
//!     preset: Preset::Default,
//!     overrides: Overrides::default(),
//! };
//! // What to do with a file dropped on the page, its name and contents (the CLI reads
//! // them with its options, from memory).
//! let loader = |name: &str, _bytes: &[u8]| -> Result<Loaded, String> {
//!     Err(format!("{name}: not accepted"))
//! };
//! let viewer = Viewer::bind(0, Box::new(loader))?;
//! println!("{}", viewer.url()); // http://127.0.0.1:PORT/?token=...
//! viewer.open(loaded);
//! viewer.serve();
//! # Ok::<(), voxreg_view::ViewError>(())
//! ```
//!
//! # Features
//!
//! None.

mod error;
mod levels;
mod model;
mod server;
mod session;
mod tuning;

pub use error::ViewError;
pub use model::{read_volume, Loaded, Volume};
pub use server::{Loader, StopHandle, Viewer};
pub use tuning::Tuning;
