//! Visualization (paper sect. 7.2.3): the 3D viewer page ([`html`]), static figures
//! ([`plots`]), the paper's Fig. 6 error histogram ([`histogram`]), and the demo report
//! ([`report`], laid out by [`demo_report`] around [`demo_figures`]).

pub mod demo_figures;
pub mod demo_report;
pub mod error;
pub mod histogram;
pub mod html;
pub mod legend;
pub mod map_plot;
pub mod plots;
pub mod report;
pub mod run_plots;
pub mod scene;
