//! Visualization (paper sect. 7.2.3): the 3D viewer page ([`html`]), static figures
//! ([`plots`]) and the demo report ([`report`]).

pub mod html;
pub mod plots;
pub mod report;
