//! The figures of tslg, as standalone SVG text: the coordinator serves them
//! to the dashboard and `tslg campaign report` writes the same ones to
//! files, so a report shows exactly what the dashboard showed.
//!
//! - [`campaign`]: the estimate with its interval band, and the relative
//!   half-width with the β line, against the number of tests on a log axis
//!   (the paper's result figures, Figs. 7, 11 and 15), and the numbers as CSV.
//! - [`heatmap`]: values over a two-dimensional grid (a library's picture).
//! - [`stages`]: an adaptive campaign's stages and support against all its
//!   tests.

pub mod axis;
pub mod campaign;
pub mod heatmap;
mod legend;
pub mod stages;
mod style;

pub use campaign::FigureError;
pub use campaign::{estimate_svg, history_csv, relative_half_width_svg};
pub use heatmap::{heatmaps_svg, Heatmap, HeatmapAxis, COLOUR_STEPS};
pub use stages::{stages_svg, support_svg};
