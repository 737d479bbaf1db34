//! What can go wrong starting the viewer.

/// What can go wrong starting the viewer.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    /// The port cannot be listened on (in use, or not permitted).
    #[error("cannot listen on 127.0.0.1:{0}: {1}")]
    Bind(u16, String),
}
