//! Where the SSIM passes work: per row, the span of pixels that can matter (see the
//! module docs of [`super`] for why nothing outside does).

use rayon::prelude::*;

use super::RADIUS;

/// A half-open range of pixel columns in one row; empty when `lo >= hi`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Span {
    pub(super) lo: usize,
    pub(super) hi: usize,
}

impl Span {
    pub(super) const EMPTY: Self = Self { lo: 0, hi: 0 };

    pub(super) fn is_empty(self) -> bool {
        self.lo >= self.hi
    }

    pub(super) fn len(self) -> usize {
        self.hi.saturating_sub(self.lo)
    }

    /// The smallest span holding both.
    pub(super) fn union(self, other: Self) -> Self {
        match (self.is_empty(), other.is_empty()) {
            (true, _) => other,
            (_, true) => self,
            _ => Self {
                lo: self.lo.min(other.lo),
                hi: self.hi.max(other.hi),
            },
        }
    }

    pub(super) fn intersect(self, other: Self) -> Self {
        Self {
            lo: self.lo.max(other.lo),
            hi: self.hi.min(other.hi),
        }
    }

    /// Widened by `r` columns each way, within a row of `w` pixels.
    pub(super) fn widen(self, r: usize, w: usize) -> Self {
        if self.is_empty() {
            return self;
        }
        Self {
            lo: self.lo.saturating_sub(r),
            hi: (self.hi + r).min(w),
        }
    }
}

/// For every row, the union of `spans` over the rows at most `RADIUS` away, widened by `widen`.
fn spread(spans: &[Span], widen: usize, w: usize, out: &mut Vec<Span>) {
    let h = spans.len();
    out.clear();
    out.extend((0..h).map(|y| {
        spans[y.saturating_sub(RADIUS)..(y + RADIUS + 1).min(h)]
            .iter()
            .fold(Span::EMPTY, |a, &s| a.union(s))
            .widen(widen, w)
    }));
}

/// Per row, where each pass works (see the module docs for why nothing outside matters).
#[derive(Debug, Default)]
pub(super) struct Spans {
    /// Pixels where x and y differ in some channel.
    pub(super) differ: Vec<Span>,
    /// Pixels whose window holds a differing pixel: where the SSIM map is computed.
    pub(super) map: Vec<Span>,
    /// Where horizontal window sums of the images are needed (the map spans of the rows
    /// within reach of the vertical pass).
    pub(super) sums: Vec<Span>,
    /// Where horizontal window sums of the map's partial derivatives are nonzero.
    pub(super) partial_sums: Vec<Span>,
    /// Pixels that receive gradient.
    pub(super) grad: Vec<Span>,
}

impl Spans {
    /// Fills the per-row spans for images `x` and `y` (RGB rows of `w` pixels).
    pub(super) fn find(&mut self, x: &[f32], y: &[f32], w: usize) {
        let sp = self;
        x.par_chunks(3 * w)
            .zip(y.par_chunks(3 * w))
            .map(|(xr, yr)| {
                let differs = |p: usize| xr[3 * p..3 * p + 3] != yr[3 * p..3 * p + 3];
                match (0..w).find(|&p| differs(p)) {
                    Some(lo) => {
                        let hi = (lo..w).rev().find(|&p| differs(p)).map_or(lo, |p| p) + 1;
                        Span { lo, hi }
                    }
                    None => Span::EMPTY,
                }
            })
            .collect_into_vec(&mut sp.differ);
        spread(&sp.differ, RADIUS, w, &mut sp.map);
        spread(&sp.map, 0, w, &mut sp.sums);
        sp.partial_sums.clear();
        sp.partial_sums
            .extend(sp.map.iter().map(|s| s.widen(RADIUS, w)));
        spread(&sp.partial_sums, 0, w, &mut sp.grad);
    }
}
