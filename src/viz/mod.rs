//! Visualization (paper sect. 7.2.3): the 3D viewer page ([`html`]), static figures
//! ([`plots`]), the demo report ([`report`]) and the paper's Fig. 6 error histogram
//! ([`histogram`]).

pub mod histogram;
pub mod html;
pub mod plots;
pub mod report;
