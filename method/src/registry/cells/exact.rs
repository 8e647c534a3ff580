//! A grid case's exact answers, by running the vehicle on every cell.

use super::Registered;
use crate::case::Case;
use crate::exact::{event_rates, exact_report, rate_probability, ExactReport};
use crate::registry::CaseError;
use crate::registry::ExactAnswers;
use crate::sampling::{LibraryDistribution, OutsideSpread, Split};
use serde::de::DeserializeOwned;
use serde::Serialize;

impl<C> ExactAnswers for Registered<C>
where
    C: Case + Send + 'static,
    C::Vehicle: DeserializeOwned + Serialize + Send + Sync + 'static,
{
    fn cell_exposures(&self) -> Result<Vec<f64>, CaseError> {
        let exposure = self.case.exposure();
        Ok((0..self.case.grid().len()).map(|c| exposure.p(c)).collect())
    }

    fn exact_event_probability(&self, spec: &serde_json::Value) -> Result<f64, CaseError> {
        let vehicle = self.builtin(spec, "an exact answer")?;
        self.unfailed(rate_probability(
            self.case.as_ref(),
            &event_rates(self.case.as_ref(), &vehicle),
        ))
    }

    fn exact_report(
        &self,
        spec: &serde_json::Value,
        file: &[u8],
        epsilon: f64,
        outside: OutsideSpread,
        beta: f64,
        confidence: f64,
    ) -> Result<ExactReport, CaseError> {
        let vehicle = self.builtin(spec, "an exact answer")?;
        let library = self.library(file)?;
        // The analytic figures are the mixture's (`Var_q(P A/q)`), which the
        // pooled variance of either split estimates.
        let q = LibraryDistribution::new(
            &library,
            self.case.exposure(),
            epsilon,
            outside,
            Split::Random,
        )?;
        self.unfailed(exact_report(
            self.case.as_ref(),
            &vehicle,
            &q,
            beta,
            confidence,
        ))
    }
}
