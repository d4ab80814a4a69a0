//! PLACEHOLDER — being written by a helper; will be overwritten.
#![allow(missing_docs)]
use nalgebra::{DMatrix, DVector};
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TestStatistic {
    pub value: f64,
    pub dof: usize,
}
#[derive(Debug, Clone)]
pub struct FisherStatistics {
    f: DMatrix<f64>,
    z: DVector<f64>,
    tol: f64,
}
impl FisherStatistics {
    pub fn new(information: DMatrix<f64>, score: DVector<f64>) -> Result<Self, ()> {
        Ok(Self {
            f: information,
            z: score,
            tol: 1e-9,
        })
    }
    pub fn with_rank_tolerance(mut self, tol: f64) -> Self {
        self.tol = tol;
        let _ = (&self.f, &self.z);
        self
    }

    pub fn global(&self) -> TestStatistic {
        let v = (self.z.transpose() * self.f.clone().try_inverse().unwrap() * &self.z)[0];
        TestStatistic {
            value: v,
            dof: self.f.nrows(),
        }
    }
    pub fn minmax(&self, a: &[usize]) -> Result<TestStatistic, ()> {
        let m = self.f.nrows();
        let b: Vec<usize> = (0..m).filter(|i| !a.contains(i)).collect();
        let fab = self.f.select_rows(a).select_columns(&b);
        let fbb = self
            .f
            .select_rows(&b)
            .select_columns(&b)
            .try_inverse()
            .unwrap();
        let faa = self.f.select_rows(a).select_columns(a);
        let za = self.z.select_rows(a);
        let zb = self.z.select_rows(&b);
        let zs = &za - &fab * &fbb * &zb;
        let fs = &faa - &fab * &fbb * fab.transpose();
        Ok(TestStatistic {
            value: (zs.transpose() * fs.try_inverse().unwrap() * &zs)[0],
            dof: a.len(),
        })
    }

    pub fn sensitivity(&self, a: &[usize]) -> Result<TestStatistic, ()> {
        let faa=self.f.select_rows(a).select_columns(a); let za=self.z.select_rows(a);
        Ok(TestStatistic{value:(za.transpose()*faa.try_inverse().unwrap()*&za)[0],dof:a.len()}) }
}
