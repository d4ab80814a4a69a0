//! The χ² detector: the classical baseline that tests one sample's normalized
//! innovation εᵀΣ⁻¹ε ~ χ²(p − q) under no fault, instead of the windowed GLR.

use crate::error::{ModelError, StepError};
use crate::filter::innovation::InnovationFilter;
use crate::isolation::FisherStatistics;
use crate::model::Dims;
use crate::model::fault::FaultDictionary;

use super::{Detector, GlrDetector, Sample, StepOutput};

/// The χ² test of εᵀΣ⁻¹ε on each sample, on the innovation of a [`GlrDetector`].
///
/// The decision statistic ([`StepOutput::glr`]) is εᵀΣ⁻¹ε and the onset the sample
/// itself: the test has no memory and no onset estimate. The GLR window runs beside it
/// unchanged: the magnitudes θ̂ are the GLR's at its own r̂, and isolation, asked at
/// the onset the χ² test reports (k), has statistics only where the window admits k
/// as an onset (s = 0).
#[derive(Debug)]
pub struct Chi2Detector {
    glr: GlrDetector,
}

impl Chi2Detector {
    /// The χ² test on `glr`'s innovation.
    #[must_use]
    pub fn new(glr: GlrDetector) -> Self {
        Self { glr }
    }

    /// The GLR detector underneath.
    #[must_use]
    pub fn glr(&self) -> &GlrDetector {
        &self.glr
    }
}

impl Detector for Chi2Detector {
    fn kind(&self) -> &'static str {
        "chi2"
    }

    fn describe(&self) -> String {
        "χ² test of εᵀΣ⁻¹ε per sample".to_owned()
    }

    fn memory(&self) -> usize {
        1
    }

    fn dims(&self) -> Dims {
        self.glr.dims()
    }

    fn faults(&self) -> &FaultDictionary {
        self.glr.faults()
    }

    fn unknown_inputs(&self) -> usize {
        self.glr.unknown_inputs()
    }

    fn next_index(&self) -> Option<u64> {
        self.glr.next_index()
    }

    fn step(&mut self, sample: &Sample<'_>, out: &mut StepOutput) -> Result<(), StepError> {
        self.glr.step(sample, out)?;
        // A statistic that is not finite stays in the output, for the caller to see.
        if out.normalized_innovation.is_finite() && out.glr.is_none_or(f64::is_finite) {
            out.glr = Some(out.normalized_innovation);
            out.onset = Some(sample.k);
        }
        Ok(())
    }

    fn predict_only(&mut self, k: u64) -> Result<(), StepError> {
        self.glr.predict_only(k)
    }

    fn restart(&mut self) -> Result<(), ModelError> {
        self.glr.restart()
    }

    fn forget_evidence(&mut self) -> bool {
        self.glr.forget_evidence()
    }

    fn fisher_statistics(&self, onset: u64) -> Option<FisherStatistics> {
        self.glr.fisher_statistics(onset)
    }

    fn onset_statistic(&self, onset: u64) -> Option<(f64, usize)> {
        self.glr.onset_statistic(onset)
    }

    fn onset_information(&self, onset: u64, information: &mut [f64], score: &mut [f64]) -> bool {
        Detector::onset_information(&self.glr, onset, information, score)
    }

    fn innovation_filter(&self) -> Option<&InnovationFilter> {
        Some(self.glr.filter())
    }
}
