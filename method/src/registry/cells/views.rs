//! What a grid case shows: a cell's parameters, a library's picture and
//! criticalities, a cell as OpenSCENARIO.

use super::Registered;
use crate::case::Case;
use crate::registry::picture::{project, PictureMap};
use crate::registry::CaseError;
use crate::registry::CaseViews;
use serde::de::DeserializeOwned;
use serde::Serialize;

impl<C> CaseViews for Registered<C>
where
    C: Case + Send + 'static,
    C::Vehicle: DeserializeOwned + Serialize + Send + Sync + 'static,
{
    fn library_picture(&self, file: &[u8]) -> Result<Vec<PictureMap>, CaseError> {
        let library = self.library(file)?;
        let grid = self.case.grid();
        let exposure = self.case.exposure();
        let (x, y) = self.case.picture_axes();
        // The library's own distribution: q(x) = V(x) / W on its cells.
        let mut q = vec![0.0; grid.len()];
        for c in &library.cells {
            q[c.cell] = c.criticality / library.w;
        }
        // The axes' titles with their units, as the case names them.
        let [x_label, y_label] = self.descriptor.picture_axes;
        let labelled = |map: PictureMap| PictureMap {
            x_label: x_label.to_owned(),
            y_label: y_label.to_owned(),
            ..map
        };
        Ok(vec![
            labelled(project(
                grid,
                |cell| exposure.p(cell),
                x,
                y,
                "exposure P(x)",
            )),
            labelled(project(grid, |cell| q[cell], x, y, "library q(x) = V(x)/W")),
        ])
    }

    fn dimension_names(&self) -> Vec<String> {
        let axes = self.case.grid().axes();
        axes.iter().map(|a| a.name().to_owned()).collect()
    }

    fn cell_values(&self, cell: usize) -> Option<Vec<f64>> {
        let grid = self.case.grid();
        (cell < grid.len()).then(|| grid.values(cell))
    }

    fn library_criticalities(
        &self,
        file: &[u8],
    ) -> Result<std::collections::HashMap<usize, f64>, CaseError> {
        let library = self.library(file)?;
        Ok(library
            .cells
            .iter()
            .map(|c| (c.cell, c.criticality))
            .collect())
    }

    fn openscenario(&self, cell: usize) -> Option<String> {
        (cell < self.case.grid().len())
            .then(|| self.case.openscenario(cell))
            .flatten()
            .map(|scene| scene.to_xosc())
    }
}
