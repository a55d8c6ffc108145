//! Sums per group in one pass: where a model fails bins its residual by each operating-point
//! signal and needs, per bin, the count and the sums of several series (the residual, its square,
//! its ranks, its centred values), and whether each bin holds two different residuals. numpy takes
//! one `bincount` pass per series; here one pass reads them all.
//!
//! Each group's sums are taken in sample order, as `numpy.bincount` takes them, so they are
//! numpy's to the last bit.

use crate::error::{ArxError, Result};

/// Counts and sums per group, and whether each group holds two different values of the first series.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupSums {
    /// Samples per group.
    pub counts: Vec<u64>,
    /// `sums[s·groups + g]`: the sum of series s over group g.
    pub sums: Vec<f64>,
    /// Whether some sample of the group differs from the group's first in the first series.
    pub varies: Vec<bool>,
}

/// [`GroupSums`] of `series` (each as long as `group`) over `groups` groups; `group[i]` is the
/// group of sample i.
///
/// # Errors
/// `ShapeMismatch` when a series' length differs from the groups'; `InvalidStructure` when a group
/// number is not below `groups`.
pub fn group_sums(group: &[u8], groups: usize, series: &[&[f64]]) -> Result<GroupSums> {
    let n = group.len();
    if let Some(s) = series.iter().find(|s| s.len() != n) {
        return Err(ArxError::ShapeMismatch { what: "samples of a grouped series".into(), expected: n, got: s.len() });
    }
    if let Some(&g) = group.iter().find(|&&g| usize::from(g) >= groups) {
        return Err(ArxError::InvalidStructure(format!("group {g} is not below the number of groups ({groups})")));
    }
    let mut out =
        GroupSums { counts: vec![0; groups], sums: vec![0.0; series.len() * groups], varies: vec![false; groups] };
    let mut first = vec![0.0; groups];
    for (i, &g) in group.iter().enumerate() {
        let g = usize::from(g);
        for (s, values) in series.iter().enumerate() {
            out.sums[s * groups + g] += values[i];
        }
        if let Some(values) = series.first() {
            if out.counts[g] == 0 {
                first[g] = values[i];
            } else if values[i] != first[g] {
                out.varies[g] = true;
            }
        }
        out.counts[g] += 1;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sums_counts_and_variation_per_group() {
        let group = [0u8, 2, 0, 2, 2, 0];
        let a = [1.0, 2.0, 1.0, 3.0, 2.0, 1.0];
        let b = [0.5, 0.25, 0.125, 1.0, 2.0, 4.0];
        let got = group_sums(&group, 4, &[&a, &b]).unwrap();
        assert_eq!(got.counts, vec![3, 0, 3, 0]);
        assert_eq!(got.sums, vec![3.0, 0.0, 7.0, 0.0, 4.625, 0.0, 3.25, 0.0]);
        assert_eq!(got.varies, vec![false, false, true, false]);
        assert_eq!(group_sums(&group, 3, &[]).unwrap().counts, vec![3, 0, 3]);
    }

    #[test]
    fn bad_groups_and_lengths_are_errors() {
        assert!(matches!(group_sums(&[0, 3], 3, &[]), Err(ArxError::InvalidStructure(_))));
        assert!(matches!(group_sums(&[0, 1], 3, &[&[1.0]]), Err(ArxError::ShapeMismatch { .. })));
    }
}
