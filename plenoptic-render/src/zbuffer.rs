//! A z-buffer that many threads can write at once: one atomic word per pixel holding
//! (depth, primitive id), resolved by `fetch_min`, or cut into bands of rows that one thread
//! each writes with plain stores ([`ZBand`]); each row remembers the span of columns it has
//! been written in, so the passes after it read (and `clear` empties) only those.

use std::ops::RangeInclusive;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

use rayon::prelude::*;

/// The empty cell: larger than any (depth, id) key.
const EMPTY: u64 = u64::MAX;

/// The key of primitive `id` at `depth` (positive): keys order by depth, then by id.
#[inline(always)]
fn key(depth: f32, id: u32) -> u64 {
    (u64::from(depth.to_bits()) << 32) | u64::from(id)
}

/// Per-pixel nearest (depth, primitive id).
///
/// The key is `depth_bits << 32 | id`: the bit pattern of a positive f32 orders like its value,
/// so the minimum key is the nearest depth, and equal depths go to the lowest id, which makes the
/// result independent of thread scheduling.
///
/// Every cell outside its row's [`ZBuffer::row_span`] is empty. A reference view of a
/// paper-scale frame covers about a tenth of its pixels, and the spans a fifth: reading whole
/// rows, the visible-point, filter and depth passes and the clear between views spent most of
/// their time on empty cells (docs/benchmarks/views.md, session 43).
pub(crate) struct ZBuffer {
    width: usize,
    cells: Vec<AtomicU64>,
    /// Per row, the least and greatest column written since the last clear (least > greatest
    /// when none has been).
    first: Vec<AtomicU32>,
    last: Vec<AtomicU32>,
}

impl ZBuffer {
    /// An empty buffer of `width` × `height` pixels.
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            cells: (0..width * height).map(|_| AtomicU64::new(EMPTY)).collect(),
            first: (0..height).map(|_| AtomicU32::new(u32::MAX)).collect(),
            last: (0..height).map(|_| AtomicU32::new(0)).collect(),
        }
    }

    /// Pixels in a row.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Rows.
    pub fn height(&self) -> usize {
        self.first.len()
    }

    /// Empties every pixel: the written span of each row (in parallel over rows).
    pub fn clear(&mut self) {
        let width = self.width;
        self.cells
            .par_chunks_mut(width.max(1))
            .zip(self.first.par_iter_mut())
            .zip(self.last.par_iter_mut())
            .with_min_len(16)
            .for_each(|((row, first), last)| {
                let (a, b) = (*first.get_mut() as usize, *last.get_mut() as usize);
                if a <= b {
                    for c in &mut row[a..=b] {
                        *c.get_mut() = EMPTY;
                    }
                }
                *first.get_mut() = u32::MAX;
                *last.get_mut() = 0;
            });
    }

    /// Keeps (depth, id) at pixel (`x`, `y`) if it is nearer than what is there. `depth` must be
    /// positive.
    #[inline]
    pub fn insert(&self, x: u32, y: u32, depth: f32, id: u32) {
        let key = key(depth, id);
        let cell = &self.cells[y as usize * self.width + x as usize];
        // A plain load first: most candidates lose, and a failed comparison costs no write.
        let old = cell.load(Ordering::Relaxed);
        if key < old {
            cell.fetch_min(key, Ordering::Relaxed);
            // Whichever insert first fills an empty cell loaded it empty, so it widens the span.
            if old == EMPTY {
                self.widen(x, y as usize);
            }
        }
    }

    /// Widens row `y`'s written span to column `x`.
    #[inline]
    fn widen(&self, x: u32, y: usize) {
        let (first, last) = (&self.first[y], &self.last[y]);
        if x < first.load(Ordering::Relaxed) {
            first.fetch_min(x, Ordering::Relaxed);
        }
        if x > last.load(Ordering::Relaxed) {
            last.fetch_max(x, Ordering::Relaxed);
        }
    }

    /// The columns of row `y` that may hold a primitive (every other cell of the row is empty),
    /// or `None` when the row is empty.
    #[inline]
    pub fn row_span(&self, y: usize) -> Option<RangeInclusive<usize>> {
        let a = self.first[y].load(Ordering::Relaxed) as usize;
        let b = self.last[y].load(Ordering::Relaxed) as usize;
        (a <= b).then_some(a..=b)
    }

    /// The rows cut into consecutive bands of `rows` rows (the last may be shorter), each to
    /// be written by one thread alone.
    pub fn bands_mut(&mut self, rows: usize) -> Vec<ZBand<'_>> {
        let (width, rows) = (self.width, rows.max(1));
        self.cells
            .chunks_mut((width * rows).max(1))
            .zip(self.first.chunks_mut(rows))
            .zip(self.last.chunks_mut(rows))
            .enumerate()
            .map(|(b, ((cells, first), last))| ZBand {
                width,
                y0: b * rows,
                cells,
                first,
                last,
            })
            .collect()
    }

    /// The nearest (depth, id) at pixel (`x`, `y`), if any primitive covers it.
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> Option<(f32, u32)> {
        let key = self.cells[y * self.width + x].load(Ordering::Relaxed);
        (key != EMPTY).then(|| (f32::from_bits((key >> 32) as u32), key as u32))
    }
}

/// Consecutive rows of a [`ZBuffer`] borrowed by one thread alone, so that its cells are read
/// and written with plain loads and stores: keeping the nearer key is a minimum and a store,
/// with no branch and no locked compare-exchange (a `fetch_min` is a compare-exchange loop on
/// x86, and whether a candidate wins is as good as random, so the branches around it were
/// mispredicted about half the time: a reference view's cube pass tests some 7 million
/// sub-pixels).
pub(crate) struct ZBand<'a> {
    width: usize,
    /// The band's first row in the buffer.
    y0: usize,
    cells: &'a mut [AtomicU64],
    first: &'a mut [AtomicU32],
    last: &'a mut [AtomicU32],
}

impl ZBand<'_> {
    /// The rows of the buffer this band holds.
    pub fn rows(&self) -> std::ops::Range<usize> {
        self.y0..self.y0 + self.first.len()
    }

    /// Whether every pixel of the rectangle `xs` × `ys` (inclusive ranges, rows inside the
    /// band) already holds a primitive nearer than `depth` (positive): then nothing at `depth`
    /// or beyond can be inserted there.
    #[inline]
    pub fn all_nearer(
        &mut self,
        depth: f32,
        (x0, x1): (usize, usize),
        (y0, y1): (usize, usize),
    ) -> bool {
        // Every key at `depth` or beyond is at least this one.
        let bound = key(depth, 0);
        let width = self.width;
        let band_y0 = self.y0;
        (y0..=y1).all(|y| {
            let r = y - band_y0;
            self.cells[r * width + x0..=r * width + x1]
                .iter_mut()
                .all(|c| *c.get_mut() < bound)
        })
    }

    /// Keeps (depth, id) at pixel (`x`, `y`) (a row inside the band) where `hit` and it is nearer
    /// than what is there; written as a select and a minimum, without a branch. `depth` must be
    /// positive where `hit`. The row's span must already reach `x` ([`ZBand::widen_rows`]).
    #[inline(always)]
    pub fn keep_nearer(&mut self, x: u32, y: usize, hit: bool, depth: f32, id: u32) {
        let r = y - self.y0;
        let candidate = if hit { key(depth, id) } else { EMPTY };
        let cell = self.cells[r * self.width + x as usize].get_mut();
        *cell = (*cell).min(candidate);
    }

    /// Widens the spans of rows `y0..=y1` (inside the band) to columns `x0..=x1`, before
    /// [`ZBand::keep_nearer`] writes there: once for a primitive's rectangle rather than at each
    /// of its cells, whose span updates were a chain of stores and loads of the same row's
    /// bounds, lane after lane. The spans may then reach beyond the written cells, until
    /// [`ZBand::tighten_spans`].
    #[inline(always)]
    pub fn widen_rows(&mut self, (x0, x1): (u32, u32), (y0, y1): (usize, usize)) {
        let (r0, r1) = (y0 - self.y0, y1 - self.y0);
        for (first, last) in self.first[r0..=r1].iter_mut().zip(&mut self.last[r0..=r1]) {
            let first = first.get_mut();
            *first = (*first).min(x0);
            let last = last.get_mut();
            *last = (*last).max(x1);
        }
    }

    /// Shrinks each row's span to its written cells' extremes (none when it has none): the
    /// spans as exact as if every write had widened them alone, whatever
    /// [`ZBand::widen_rows`] covered.
    pub fn tighten_spans(&mut self) {
        let width = self.width;
        for ((row, first), last) in self
            .cells
            .chunks_mut(width.max(1))
            .zip(self.first.iter_mut())
            .zip(self.last.iter_mut())
        {
            let (a, b) = (*first.get_mut() as usize, *last.get_mut() as usize);
            if a > b {
                continue;
            }
            let span = &mut row[a..=b];
            match span.iter_mut().position(|c| *c.get_mut() != EMPTY) {
                Some(lo) => {
                    let hi = span.iter_mut().rposition(|c| *c.get_mut() != EMPTY);
                    *first.get_mut() = (a + lo) as u32;
                    *last.get_mut() = (a + hi.unwrap_or(lo)) as u32;
                }
                None => {
                    *first.get_mut() = u32::MAX;
                    *last.get_mut() = 0;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_the_nearest_and_breaks_ties_by_id() {
        let z = ZBuffer::new(2, 1);
        assert_eq!(z.get(0, 0), None);
        z.insert(0, 0, 5.0, 7);
        z.insert(0, 0, 6.0, 1);
        assert_eq!(z.get(0, 0), Some((5.0, 7)));
        z.insert(0, 0, 5.0, 3);
        assert_eq!(z.get(0, 0), Some((5.0, 3)));
        z.insert(0, 0, 0.25, 9);
        assert_eq!(z.get(0, 0), Some((0.25, 9)));
        assert_eq!(z.get(1, 0), None);
    }

    /// Bands cover the rows in order; keeping through a band is the same minimum as inserting
    /// (nearest depth, ties to the lowest id, misses leave cells alone), the spans widened over
    /// rectangles and then tightened are the written columns' extremes, and `all_nearer`
    /// answers as a look at every cell would.
    #[test]
    fn bands_keep_the_nearest_like_inserts_do() {
        let (w, h) = (37usize, 23usize);
        let mut seed = 7u64;
        let mut next = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            seed >> 33
        };
        let writes: Vec<(u32, usize, bool, f32, u32)> = (0..3000)
            .map(|_| {
                let (x, y) = ((next() % w as u64) as u32, (next() % 19) as usize);
                (
                    x,
                    y,
                    next() % 4 != 0,
                    1.0 + (next() % 50) as f32,
                    (next() % 9) as u32,
                )
            })
            .collect();
        let atomic = ZBuffer::new(w, h);
        for &(x, y, hit, d, id) in &writes {
            if hit {
                atomic.insert(x, y as u32, d, id);
            }
        }
        let mut banded = ZBuffer::new(w, h);
        let mut bands = banded.bands_mut(5);
        assert_eq!(
            bands.iter().map(ZBand::rows).collect::<Vec<_>>(),
            vec![0..5, 5..10, 10..15, 15..20, 20..23]
        );
        // Each write's row widened first over a rectangle around it, missed or not, as a
        // primitive's rectangle is; the spans are tightened at the end.
        for &(x, y, hit, d, id) in &writes {
            let band = &mut bands[y / 5];
            let rows = band.rows();
            let (x0, x1) = (
                x.saturating_sub(next() as u32 % 4),
                (x + next() as u32 % 4).min(w as u32 - 1),
            );
            let (y0, y1) = (
                y.saturating_sub(next() as usize % 3).max(rows.start),
                (y + next() as usize % 3).min(rows.end - 1),
            );
            band.widen_rows((x0, x1), (y0, y1));
            band.keep_nearer(x, y, hit, d, id);
        }
        for band in &mut bands {
            for _ in 0..200 {
                let rows = band.rows();
                let (a, b) = ((next() % w as u64) as usize, (next() % w as u64) as usize);
                let y0 = rows.start + (next() as usize % rows.len());
                let y1 = y0 + (next() as usize % (rows.end - y0));
                let depth = 1.0 + (next() % 60) as f32;
                let want = (y0..=y1).all(|y| {
                    (a.min(b)..=a.max(b)).all(|x| atomic.get(x, y).is_some_and(|(z, _)| z < depth))
                });
                assert_eq!(band.all_nearer(depth, (a.min(b), a.max(b)), (y0, y1)), want);
            }
        }
        for band in &mut bands {
            band.tighten_spans();
        }
        drop(bands);
        for y in 0..h {
            assert_eq!(banded.row_span(y), atomic.row_span(y), "row {y}");
            for x in 0..w {
                assert_eq!(banded.get(x, y), atomic.get(x, y), "pixel ({x}, {y})");
            }
        }
        assert!((19..h).all(|y| banded.row_span(y).is_none()));
    }

    /// Inserts from many threads at once: every written cell lies in its row's span, the spans
    /// are exactly the written columns' extremes, and a clear empties everything and resets them.
    #[test]
    fn spans_hold_every_written_cell_and_clear_empties_them() {
        let (w, h) = (97usize, 31usize);
        let mut z = ZBuffer::new(w, h);
        let mut seed = 5u64;
        let mut writes: Vec<(u32, u32, f32)> = (0..4000)
            .map(|_| {
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let r = seed >> 33;
                (
                    (r % w as u64) as u32,
                    ((r / 97) % 23) as u32,
                    1.0 + (r % 1000) as f32,
                )
            })
            .collect();
        // Row 5 written at one column only; rows 23.. never.
        writes.push((40, 5, 0.5));
        writes.retain(|&(x, y, _)| y != 5 || x == 40);
        for round in 0..2 {
            writes
                .par_iter()
                .enumerate()
                .for_each(|(i, &(x, y, d))| z.insert(x, y, d, i as u32));
            for y in 0..h {
                let cols: Vec<usize> = (0..w).filter(|&x| z.get(x, y).is_some()).collect();
                let span = z.row_span(y);
                match cols.first() {
                    None => assert_eq!(span, None, "row {y}, round {round}"),
                    Some(&a) => assert_eq!(span, Some(a..=*cols.last().unwrap()), "row {y}"),
                }
            }
            assert_eq!(z.row_span(5), Some(40..=40));
            z.clear();
            assert!((0..h).all(|y| z.row_span(y).is_none()));
            assert!((0..h).all(|y| (0..w).all(|x| z.get(x, y).is_none())));
        }
    }
}
