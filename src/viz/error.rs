//! The one way a figure fails: it could not be drawn.

/// A figure could not be drawn (e.g. no font for its text on this machine).
#[derive(Debug, thiserror::Error)]
#[error("cannot draw figure: {0}")]
pub struct PlotError(pub String);

impl PlotError {
    /// From an error of the drawing backend (plotters' errors carry their cause in `Debug`).
    pub(crate) fn drawing<E: std::fmt::Debug>(e: E) -> Self {
        PlotError(format!("{e:?}"))
    }
}
