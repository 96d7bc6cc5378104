//! Point clouds drawn as the PccAppRenderer draws them: voxel cubes (or discs), z-buffered,
//! coloured towards the viewer.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Mutex, PoisonError};

use camera_model::Camera;
use glam::Vec3;
use plenoptic_io::PlenopticCloud;
use rayon::prelude::*;

use crate::camera::ViewCamera;
use crate::cpu::has_avx2;
use crate::pixels::{render_supersampled, resolve};
use crate::shading::{Shader, ShadingColours};
use crate::zbuffer::{ZBand, ZBuffer};
use crate::{Error, PointShape, ViewImage, ViewOptions};

/// Points per parallel work item of the visibility pass.
const CHUNK: usize = 16_384;

/// Renders a (plenoptic) point cloud from `camera`.
///
/// Each point is a cube of side `opts.point_size` (grown to close a sparse cloud's surface when
/// `opts.close_surface` is set: [`crate::closing_point_size`]) centred on it, axis-aligned in the cloud's frame
/// (PccAppRenderer `--type 0`), or a view-aligned disc (`--type 1`). A point is drawn only when
/// its primitive lies wholly in front of the camera: the cube's camera-space bounding box, or the
/// ball of the disc's radius. So a point at the camera centre, or within a point size of it, is
/// not drawn (rather than filling the image, or depending on the rounding of its depth). The colour of a point is
/// [`interpolate`](plenoptic_io::view_color::interpolate)d towards the camera centre from its per-camera colours and the capture-camera
/// positions (main colour when the cloud has no rig or no camera faces the viewer). The cloud is
/// drawn in its own (voxel) frame, where the rig positions live.
pub fn render_cloud(
    cloud: &PlenopticCloud,
    camera: &Camera,
    opts: &ViewOptions,
) -> Result<ViewImage, Error> {
    PreparedCloud::new(cloud, opts)?.render(camera)
}

/// A cloud made ready to be drawn from many cameras: checked, its point size chosen
/// ([`ViewOptions::for_cloud`]), its capture cameras' positions gathered and its points put in
/// Morton order, once rather than once a view.
pub(crate) struct PreparedCloud<'a> {
    cloud: &'a PlenopticCloud,
    capture: Vec<Vec3>,
    /// The points' colours in Morton order, the order the visibility pass draws them in and
    /// keys the z-buffer by (their rank in it): consecutive points write neighbouring pixels,
    /// and the shading pass reads neighbouring colours.
    colours: ShadingColours,
    /// The points' positions in that order. Read through an index list instead, a paper-scale
    /// frame listed in random order spent half its drawing time waiting for positions from memory
    /// (docs/benchmarks/views.md).
    positions: Vec<Vec3>,
    /// The box of each run of [`RUN`] consecutive positions (a small patch of surface, the
    /// order being Morton's): the cube pass draws the runs nearest first, each in the bands of
    /// rows its box reaches.
    runs: Vec<RunBox>,
    opts: ViewOptions,
    /// Per-view buffers of views already drawn, for the next views to reuse.
    buffers: ViewBuffersPool,
}

/// What drawing one view needs besides its image: the z-buffer, the visible flags, the
/// visible points' colours by rank, and the visible ranks with their shaded colours in rank
/// order. At 1024² supersampled 3× and 3M points that is 75 + 3 + 38 MB, and 4 + 12 MB for a
/// view that sees a million points; allocated afresh for each of a frame's 44 views, the pages'
/// first touch (the kernel zeroing them, one fault a page) and the z-buffer's serial fill cost
/// about a twentieth of the views' time.
struct ViewBuffers {
    zbuf: ZBuffer,
    visible: Vec<AtomicBool>,
    colours: Vec<[f32; 3]>,
    ranks: Vec<u32>,
    shaded: Vec<[f32; 3]>,
}

/// Buffers of finished views, kept for the next views to start. As many sets wait as there are
/// threads, and no more than views are still to start when the caller said how many
/// ([`PreparedCloud::expect_views`]). On two threads two views are in flight, and when both
/// finished together a pool of one dropped the second set, so the next pair allocated one
/// afresh (5 sets for a frame's 44 views instead of 2; the kernel's page clearing and faults
/// were about a twelfth of the views' time). Not every set ever taken: rayon's stealing can put
/// more views in flight than threads for a moment, and sets kept while a frame's last views
/// finish are never used again (keeping every set raised a 16-thread paper-scale run's peak from
/// 3.29 to 4.19 GB, `4c0524b`).
struct ViewBuffersPool {
    waiting: Mutex<Vec<ViewBuffers>>,
    /// Views still to start, or `usize::MAX` when the caller has not said.
    to_come: AtomicUsize,
}

impl Default for ViewBuffersPool {
    fn default() -> Self {
        Self {
            waiting: Mutex::default(),
            to_come: AtomicUsize::new(usize::MAX),
        }
    }
}

impl ViewBuffersPool {
    /// A set for a view of `width` × `height` sub-pixels and `points` points: the z-buffer empty
    /// and no point visible. The colours are left as the last view wrote them: a view reads the
    /// colour of a rank only after it has shaded that rank; the ranks and shaded colours are
    /// refilled by each view.
    fn take(&self, width: usize, height: usize, points: usize) -> ViewBuffers {
        // One view fewer to come (unless the count is unknown or already spent).
        let _ = self
            .to_come
            .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| {
                (n != usize::MAX && n > 0).then(|| n - 1)
            });
        let reused = self
            .waiting
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .pop();
        match reused {
            Some(mut b)
                if (b.zbuf.width(), b.zbuf.height()) == (width, height)
                    && b.visible.len() == points =>
            {
                b.zbuf.clear();
                b.visible
                    .par_iter_mut()
                    .with_min_len(CHUNK)
                    .for_each(|v| *v.get_mut() = false);
                b
            }
            _ => ViewBuffers {
                zbuf: ZBuffer::new(width, height),
                visible: (0..points).map(|_| AtomicBool::new(false)).collect(),
                colours: vec![[0.0; 3]; points],
                ranks: Vec::new(),
                shaded: Vec::new(),
            },
        }
    }

    /// Returns a set for a later view, or frees it when as many sets are already waiting as
    /// there are threads or views to come.
    fn give_back(&self, b: ViewBuffers) {
        let keep = rayon::current_num_threads().min(self.to_come.load(Ordering::Relaxed));
        let mut waiting = self.waiting.lock().unwrap_or_else(PoisonError::into_inner);
        if waiting.len() < keep {
            waiting.push(b);
        }
    }
}

impl<'a> PreparedCloud<'a> {
    /// Checks `cloud` and `opts` and prepares the cloud for drawing.
    pub(crate) fn new(cloud: &'a PlenopticCloud, opts: &ViewOptions) -> Result<Self, Error> {
        opts.validate()?;
        check_cloud(cloud)?;
        let order = plenoptic_io::morton_order(&cloud.positions);
        let positions: Vec<Vec3> = order
            .par_iter()
            .map(|&i| cloud.positions[i as usize])
            .collect();
        let runs = run_boxes(&positions);
        let colours = ShadingColours::new(cloud, &order);
        Ok(Self {
            cloud,
            capture: cloud.camera_positions(),
            colours,
            positions,
            runs,
            opts: opts.for_cloud(cloud),
            buffers: ViewBuffersPool::default(),
        })
    }

    /// Tells the cloud that `n` more views are to be drawn, so that it keeps no buffers for
    /// views that will not come.
    pub(crate) fn expect_views(&self, n: usize) {
        self.buffers.to_come.store(n, Ordering::Relaxed);
    }

    /// The cloud seen from `camera`.
    pub(crate) fn render(&self, camera: &Camera) -> Result<ViewImage, Error> {
        render_supersampled(camera, &self.opts, |cam| self.render_once(cam))
    }

    /// One render at the camera's own resolution, filtered down to the output's.
    fn render_once(&self, camera: &Camera) -> Result<ViewImage, Error> {
        let (cloud, opts) = (self.cloud, &self.opts);
        let view = ViewCamera::new(camera)?;
        let (width, height) = (view.width as usize, view.height as usize);
        let mut buffers = self.buffers.take(width, height, cloud.len());
        let ViewBuffers {
            zbuf,
            visible,
            colours,
            ranks,
            shaded,
        } = &mut buffers;
        match opts.point_shape {
            PointShape::Cube => {
                _ = draw_cubes(
                    &self.positions,
                    &self.runs,
                    &view,
                    0.5 * opts.point_size,
                    zbuf,
                )
            }
            PointShape::Disc => {
                draw_discs(&self.positions, &view, disc_radius(opts.point_size), zbuf)
            }
        }
        // A point's colour depends on the point and the viewer, not on the pixel: shade each
        // visible point once rather than each of its pixels (a supersampled point covers many).
        (0..height).into_par_iter().with_min_len(16).for_each(|y| {
            for x in zbuf.row_span(y).into_iter().flatten() {
                if let Some((_, rank)) = zbuf.get(x, y) {
                    visible[rank as usize].store(true, Ordering::Relaxed);
                }
            }
        });
        // The visible points' ranks, increasing: their colours are read forwards.
        ranks.clear();
        ranks.par_extend(
            visible
                .par_iter()
                .with_min_len(CHUNK)
                .enumerate()
                .filter(|(_, v)| v.load(Ordering::Relaxed))
                .map(|(rank, _)| rank as u32),
        );
        let shader = Shader {
            positions: &self.positions,
            colours: &self.colours,
            capture: &self.capture,
            viewer: view.center,
            exponent: opts.exponent,
        };
        let avx2 = has_avx2();
        shaded.resize(ranks.len(), [0.0; 3]);
        shaded
            .par_chunks_mut(CHUNK)
            .zip(ranks.par_chunks(CHUNK))
            .for_each(|(out, ranks)| shader.shade(ranks, out, avx2));
        for (&rank, &colour) in ranks.iter().zip(shaded.iter()) {
            colours[rank as usize] = colour;
        }
        // Every rank the z-buffer holds is visible, so shaded this view: no stale colour of an
        // earlier view is read.
        let image = resolve(&view, zbuf, opts, |rank, _, _| colours[rank as usize]);
        self.buffers.give_back(buffers);
        Ok(image)
    }
}

/// Checks that the cloud's arrays agree and that ids fit the z-buffer.
fn check_cloud(cloud: &PlenopticCloud) -> Result<(), Error> {
    let n = cloud.len();
    if n >= u32::MAX as usize {
        return Err(Error::InvalidModel(format!(
            "{n} points exceed the renderer's limit of {}",
            u32::MAX - 1
        )));
    }
    if cloud.colors.len() != n {
        return Err(Error::InvalidModel(format!(
            "{n} points but {} main colours",
            cloud.colors.len()
        )));
    }
    if cloud.camera_colors.len() != n * cloud.num_cameras {
        return Err(Error::InvalidModel(format!(
            "{n} points × {} cameras but {} per-camera colours",
            cloud.num_cameras,
            cloud.camera_colors.len()
        )));
    }
    Ok(())
}

/// Radius of the PccAppRenderer's disc: its fragment shader keeps exp(−|c|²) ≥ 0.5 on a quad of
/// half-size `point_size`, i.e. |c| ≤ √ln 2 half-sizes.
fn disc_radius(point_size: f32) -> f32 {
    std::f32::consts::LN_2.sqrt() * point_size
}

/// Points in a run that the cube pass orders, and tests for occlusion, as one (by the run's
/// centre and box).
const RUN: usize = 64;

/// Where a run's cubes can reach on the screen of one view.
#[derive(Clone, Copy, Debug)]
enum RunReach {
    /// Off the image.
    Nowhere,
    /// Its box reaches behind the camera: its cubes are bounded one by one, on every row.
    Everywhere,
    /// Within the pixel rectangle `(x0, x1, y0, y1)`, at depths from `bound` on (the near side
    /// of its camera-space box, lowered as [`DEPTH_BOUND_SLACK`] says).
    Rectangle {
        rect: (u32, u32, u32, u32),
        bound: f32,
    },
}

/// Cubes the cube pass moves into camera space and bounds on the screen at once (one AVX2
/// vector of f32).
const CUBE_LANES: usize = 8;

/// The box of the points of one run of [`RUN`] consecutive positions.
#[derive(Clone, Copy, Debug)]
struct RunBox {
    lo: Vec3,
    hi: Vec3,
}

impl RunBox {
    fn centre(self) -> Vec3 {
        0.5 * (self.lo + self.hi)
    }
}

/// The boxes of the runs of [`RUN`] consecutive `positions`.
fn run_boxes(positions: &[Vec3]) -> Vec<RunBox> {
    positions
        .par_chunks(RUN)
        .map(|run| {
            let (lo, hi) = run.iter().fold(
                (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
                |(lo, hi), &p| (lo.min(p), hi.max(p)),
            );
            RunBox { lo, hi }
        })
        .collect()
}

/// Fewest bands of rows the cube pass cuts a view's z-buffer into (more on a machine with more
/// threads, one a thread): each band is drawn by one thread alone, with plain stores
/// ([`ZBand`]), the bands of a view in parallel. A run whose box straddles bands is projected
/// in each, so fewer, taller bands repeat less.
const MIN_BANDS: usize = 4;

/// Visibility pass for cubes of half-side `h` centred on `positions` (whose runs of [`RUN`]
/// have the boxes `runs`): each pixel whose centre ray hits a cube records the entry depth
/// (camera z) of the nearest hit and the cube's index. Returns how many times a band skipped a
/// whole run as hidden.
fn draw_cubes(
    positions: &[Vec3],
    runs: &[RunBox],
    view: &ViewCamera,
    h: f32,
    zbuf: &mut ZBuffer,
) -> usize {
    draw_cubes_using(positions, runs, view, h, zbuf, has_avx2())
}

/// [`draw_cubes`] with the AVX2 instantiation or without it.
///
/// The z-buffer is cut into bands of rows ([`MIN_BANDS`] or more), drawn in parallel, each by
/// one thread. A band draws the runs whose box reaches its rows, nearest first, so by the time
/// a run on the far side of the object comes, the near side usually covers its cubes'
/// rectangles and most of them are skipped ([`ZBand::all_nearer`]): the whole run at once when
/// its own rectangle is covered nearer than its box (about three runs in ten of a paper-scale
/// frame's view, run and band pairs counted), else cube by cube. The z-buffer ends the same in
/// any order and for any bands: it keeps the least (depth, rank) key of each pixel.
fn draw_cubes_using(
    positions: &[Vec3],
    runs: &[RunBox],
    view: &ViewCamera,
    h: f32,
    zbuf: &mut ZBuffer,
    avx2: bool,
) -> usize {
    let r = view.rotation;
    // Camera-space half-extents of a world-axis-aligned box of half-sides `half`: |R|·half.
    let extent_of = |half: Vec3| {
        Vec3::new(
            r.x_axis.x.abs() * half.x + r.y_axis.x.abs() * half.y + r.z_axis.x.abs() * half.z,
            r.x_axis.y.abs() * half.x + r.y_axis.y.abs() * half.y + r.z_axis.y.abs() * half.z,
            r.x_axis.z.abs() * half.x + r.y_axis.z.abs() * half.y + r.z_axis.z.abs() * half.z,
        )
    };
    let cubes = Cubes {
        view,
        h,
        extent: Vec3::new(
            h * (r.x_axis.x.abs() + r.y_axis.x.abs() + r.z_axis.x.abs()),
            h * (r.x_axis.y.abs() + r.y_axis.y.abs() + r.z_axis.y.abs()),
            h * (r.x_axis.z.abs() + r.y_axis.z.abs() + r.z_axis.z.abs()),
        ),
    };
    // Each run nearest first, with the rectangle its cubes can reach: that of its box (the
    // points' box grown by the cube's half-side) in camera space, grown again by a margin far
    // above the rounding of the cubes' own boxes, so that it holds each cube's rectangle and
    // its near side is no farther than any cube's; everywhere when the box reaches behind the
    // camera (its cubes are then bounded one by one), nowhere when it is off the image.
    let mut order: Vec<(f32, u32, RunReach)> = runs
        .iter()
        .enumerate()
        .map(|(run, b)| {
            let centre = view.rotation * b.centre() + view.translation;
            let half = extent_of(0.5 * (b.hi - b.lo) + Vec3::splat(h));
            let margin = half * 1e-4 + Vec3::splat(1e-4 * (h + centre.abs().max_element()));
            let (lo, hi) = (centre - half - margin, centre + half + margin);
            let reach = if lo.z > 0.0 {
                view.pixel_range(lo, hi)
                    .map_or(RunReach::Nowhere, |rect| RunReach::Rectangle {
                        rect,
                        bound: lo.z * DEPTH_BOUND_SLACK,
                    })
            } else {
                RunReach::Everywhere
            };
            (centre.z, run as u32, reach)
        })
        .collect();
    order.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let bands = MIN_BANDS.max(rayon::current_num_threads());
    let rows_per_band = (view.height as usize).div_ceil(bands);
    zbuf.bands_mut(rows_per_band)
        .into_par_iter()
        .map(|mut band| {
            let rows = band.rows();
            let (b0, b1) = (rows.start as u32, rows.end as u32);
            let mut hidden_runs = 0;
            for &(_, run, reach) in &order {
                let hidden = match reach {
                    RunReach::Nowhere => true,
                    RunReach::Everywhere => false,
                    RunReach::Rectangle {
                        rect: (x0, x1, y0, y1),
                        bound,
                    } => {
                        let (y0, y1) = (y0.max(b0), y1.min(b1 - 1));
                        // Outside the band, or behind everything its rectangle already holds
                        // there: none of its cubes could win a pixel of the band.
                        y0 > y1 || {
                            let behind = band.all_nearer(
                                bound,
                                (x0 as usize, x1 as usize),
                                (y0 as usize, y1 as usize),
                            );
                            hidden_runs += usize::from(behind);
                            behind
                        }
                    }
                };
                if !hidden {
                    let first = run as usize * RUN;
                    let points = &positions[first..(first + RUN).min(positions.len())];
                    cubes.draw(points, first, &mut band, avx2);
                }
            }
            band.tighten_spans();
            hidden_runs
        })
        .sum()
}

/// A cube's entry depth along a pixel ray is at least the near side of its camera-space box;
/// this factor keeps the bound below the entry depths as the slab test rounds them (a few
/// units in the last place of f32, from the ray's direction and the divisions), so a cube
/// skipped by it could not have won a pixel.
const DEPTH_BOUND_SLACK: f32 = 1.0 - 1e-5;

/// What every cube of one view's visibility pass shares.
struct Cubes<'a> {
    view: &'a ViewCamera,
    /// Half the cube's side.
    h: f32,
    /// Camera-space half-extents of the cube's bounding box.
    extent: Vec3,
}

impl Cubes<'_> {
    /// Draws the parts in `band` of the cubes centred on `points`, the first of rank `first`:
    /// the AVX2 instantiation where the CPU has it (rounding and division become single
    /// instructions instead of library calls), else the portable one; the same operations in
    /// the same order, so the same bits either way.
    fn draw(&self, points: &[Vec3], first: usize, band: &mut ZBand<'_>, avx2: bool) {
        #[cfg(target_arch = "x86_64")]
        if avx2 {
            // SAFETY: `avx2` is only true when `has_avx2()` is, so the CPU has AVX2.
            #[allow(unsafe_code)]
            return unsafe { self.draw_avx2(points, first, band) };
        }
        let _ = avx2;
        self.draw_portable(points, first, band);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn draw_avx2(&self, points: &[Vec3], first: usize, band: &mut ZBand<'_>) {
        self.draw_portable(points, first, band);
    }

    /// The cubes are moved into camera space and bounded on the screen [`CUBE_LANES`] at a
    /// time (bounding 3 million cubes a view one at a time, four divisions each, took a fifth
    /// of the pass), then drawn one by one, each over the rows of its rectangle in the band.
    #[inline(always)]
    fn draw_portable(&self, points: &[Vec3], first: usize, band: &mut ZBand<'_>) {
        let extent = self.extent;
        let rows = band.rows();
        let (b0, b1) = (rows.start as u32, rows.end as u32 - 1);
        for (g, group) in points.chunks(CUBE_LANES).enumerate() {
            // A short last group repeats its first point in the spare lanes.
            let lanes: [Vec3; CUBE_LANES] =
                std::array::from_fn(|l| *group.get(l).unwrap_or(&group[0]));
            let centres = self.view.camera_space_lanes(&lanes);
            let lo = std::array::from_fn(|axis| centres[axis].map(|c| c - extent[axis]));
            let hi = std::array::from_fn(|axis| centres[axis].map(|c| c + extent[axis]));
            let ranges = self.view.pixel_ranges(lo, hi);
            for (l, &p) in group.iter().enumerate() {
                if let Some((x0, x1, y0, y1)) = ranges[l] {
                    let (y0, y1) = (y0.max(b0), y1.min(b1));
                    if y0 <= y1 {
                        let rank = (first + g * CUBE_LANES + l) as u32;
                        self.draw_cube(p, lo[2][l], (x0, x1, y0, y1), rank, band);
                    }
                }
            }
        }
    }

    /// Draws the cube centred on `p` whose camera-space box starts at depth `near` over the
    /// pixel rectangle `(x0, x1, y0, y1)` (its rows inside `band`).
    #[inline(always)]
    fn draw_cube(
        &self,
        p: Vec3,
        near: f32,
        (x0, x1, y0, y1): (u32, u32, u32, u32),
        rank: u32,
        band: &mut ZBand<'_>,
    ) {
        let view = self.view;
        let bound = near * DEPTH_BOUND_SLACK;
        // A cube behind everything its rectangle already holds cannot win a pixel: skip
        // its slab tests (the z-buffer ends the same whatever the order of the cubes).
        if band.all_nearer(
            bound,
            (x0 as usize, x1 as usize),
            (y0 as usize, y1 as usize),
        ) {
            return;
        }
        // Slab test in world axes, relative to the camera centre for precision; every pixel of
        // the rectangle is tested and the nearer key kept without a branch (testing first
        // whether a pixel already holds something nearer was a branch mispredicted as often
        // as not).
        let rel = p - view.center;
        let (lo, hi) = (rel - self.h, rel + self.h);
        // The rectangle's cells row by row, [`SLAB_LANES`] at a time (a cube's rectangle holds
        // about six, over two or three short rows): the rays and slab tests of a group in
        // vector operations, then each cell's key kept on its own. A group starts `c` columns
        // into row `y`; its lanes' cells follow from `c` and the width alone, so no lane is
        // stored one by one and read back as a vector (which stalled each group). The rows'
        // spans are widened once for the whole rectangle, not lane by lane, and the band
        // tightens them when it is drawn.
        let width = (x1 - x0 + 1) as usize;
        let cells = width * (y1 - y0 + 1) as usize;
        band.widen_rows((x0, x1), (y0 as usize, y1 as usize));
        let (mut c, mut y) = (0, y0);
        for start in (0..cells).step_by(SLAB_LANES) {
            let n = (cells - start).min(SLAB_LANES);
            let (dx, dy) = lane_cells(width, c);
            let xs: [u32; SLAB_LANES] = std::array::from_fn(|l| x0 + dx[l]);
            let ys: [u32; SLAB_LANES] = std::array::from_fn(|l| y + dy[l]);
            let (near, far) = slab_lanes(view.world_rays(&xs, &ys), lo, hi);
            for l in 0..n {
                let hit = near[l] <= far[l] && near[l] > 0.0;
                band.keep_nearer(xs[l], ys[l] as usize, hit, near[l], rank);
            }
            if start + SLAB_LANES < cells {
                let next = c + SLAB_LANES;
                (c, y) = (next % width, y + (next / width) as u32);
            }
        }
    }
}

/// Pixels of a cube's rectangle whose rays [`Cubes::draw_cube`] makes and slab-tests at once
/// (one AVX2 vector of f32).
const SLAB_LANES: usize = 8;

/// Lane `l`'s cell, `(columns, rows)` on from the cell `c` columns into a row of a rectangle
/// `width` cells wide: `((c + l) % width, (c + l) / width)`, from a table for the narrow
/// rectangles whose group of lanes wraps more than once.
#[inline(always)]
fn lane_cells(width: usize, c: usize) -> ([u32; SLAB_LANES], [u32; SLAB_LANES]) {
    if width < SLAB_LANES {
        LANE_CELLS[width][c]
    } else {
        let w = width as u32;
        let k: [u32; SLAB_LANES] = std::array::from_fn(|l| (c + l) as u32);
        (
            std::array::from_fn(|l| if k[l] >= w { k[l] - w } else { k[l] }),
            std::array::from_fn(|l| u32::from(k[l] >= w)),
        )
    }
}

/// [`lane_cells`] of the rectangles narrower than [`SLAB_LANES`], by width and start column.
static LANE_CELLS: [[([u32; SLAB_LANES], [u32; SLAB_LANES]); SLAB_LANES]; SLAB_LANES] = {
    let mut table = [[([0; SLAB_LANES], [0; SLAB_LANES]); SLAB_LANES]; SLAB_LANES];
    let mut width = 1;
    while width < SLAB_LANES {
        let mut c = 0;
        while c < width {
            let mut l = 0;
            while l < SLAB_LANES {
                table[width][c].0[l] = ((c + l) % width) as u32;
                table[width][c].1[l] = ((c + l) / width) as u32;
                l += 1;
            }
            c += 1;
        }
        width += 1;
    }
    table
};

/// Where the rays `d[axis][lane]` from the camera centre enter and leave the world-axis box
/// [`lo`, `hi`] (relative to the centre), `(near, far)` per lane, the ray parameter being camera
/// z; the box is hit where near ≤ far and near > 0. Written lane by lane for 8-wide vectors,
/// with glam's `Vec3` arithmetic on each lane: `t0 = lo · d⁻¹`, `t1 = hi · d⁻¹`, near the
/// largest of the axes' `min(t0, t1)`, far the least of their `max(t0, t1)`, minima and maxima
/// as glam takes them (`a < b ? a : b`), so the same bits as the one-ray form.
#[inline(always)]
fn slab_lanes<const N: usize>(d: [[f32; N]; 3], lo: Vec3, hi: Vec3) -> ([f32; N], [f32; N]) {
    let min = |a: f32, b: f32| if a < b { a } else { b };
    let max = |a: f32, b: f32| if a > b { a } else { b };
    let entry_exit = |axis: usize| -> ([f32; N], [f32; N]) {
        let inv: [f32; N] = std::array::from_fn(|l| 1.0 / d[axis][l]);
        let t0: [f32; N] = std::array::from_fn(|l| lo[axis] * inv[l]);
        let t1: [f32; N] = std::array::from_fn(|l| hi[axis] * inv[l]);
        (
            std::array::from_fn(|l| min(t0[l], t1[l])),
            std::array::from_fn(|l| max(t0[l], t1[l])),
        )
    };
    let ([in_x, in_y, in_z], [out_x, out_y, out_z]) = {
        let (x, y, z) = (entry_exit(0), entry_exit(1), entry_exit(2));
        ([x.0, y.0, z.0], [x.1, y.1, z.1])
    };
    (
        std::array::from_fn(|l| max(in_x[l], max(in_y[l], in_z[l]))),
        std::array::from_fn(|l| min(out_x[l], min(out_y[l], out_z[l]))),
    )
}

/// Visibility pass for view-aligned discs of radius `radius` at the point's depth, keyed by
/// index as [`draw_cubes`] does; a disc whose centre is not more than `radius` in front of the
/// camera is not drawn (see [`render_cloud`]).
fn draw_discs(positions: &[Vec3], view: &ViewCamera, radius: f32, zbuf: &ZBuffer) {
    let extent = Vec3::new(radius, radius, 0.0);
    let r2 = radius * radius;
    positions
        .par_chunks(CHUNK)
        .enumerate()
        .for_each(|(chunk, points)| {
            for (j, &p) in points.iter().enumerate() {
                let c = view.rotation * p + view.translation;
                if c.z <= radius {
                    continue;
                }
                let Some((x0, x1, y0, y1)) = view.pixel_range(c - extent, c + extent) else {
                    continue;
                };
                let rank = (chunk * CHUNK + j) as u32;
                for y in y0..=y1 {
                    for x in x0..=x1 {
                        // The pixel ray meets the disc's plane z = c.z at camera_ray·c.z.
                        let q = view.camera_ray(x, y) * c.z;
                        let (dx, dy) = (q.x - c.x, q.y - c.y);
                        if dx * dx + dy * dy <= r2 {
                            zbuf.insert(x, y, c.z, rank);
                        }
                    }
                }
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pool of `n` threads for the tests that compare thread counts or run views at once.
    fn thread_pool(n: usize) -> rayon::ThreadPool {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
    }
    use camera_model::{Intrinsics, Pose};
    use glam::DVec3;
    use plenoptic_io::CaptureCamera;

    fn cloud_of(positions: Vec<Vec3>, colors: Vec<[f32; 3]>) -> PlenopticCloud {
        PlenopticCloud {
            positions,
            colors,
            ..Default::default()
        }
    }

    fn camera(eye: DVec3, target: DVec3, w: u32, h: u32, fov: f64) -> Camera {
        Camera::new(
            Intrinsics::from_fov_y(w, h, fov),
            Pose::look_at(eye, target, DVec3::Y),
        )
    }

    /// A closed voxelised sphere shell: voxels inside the ball with a 6-neighbour outside.
    fn voxel_sphere(radius: f32) -> Vec<Vec3> {
        let r = radius.ceil() as i32 + 1;
        let inside = |x: i32, y: i32, z: i32| ((x * x + y * y + z * z) as f32) <= radius * radius;
        let mut out = Vec::new();
        for x in -r..=r {
            for y in -r..=r {
                for z in -r..=r {
                    if inside(x, y, z)
                        && [
                            (1, 0, 0),
                            (-1, 0, 0),
                            (0, 1, 0),
                            (0, -1, 0),
                            (0, 0, 1),
                            (0, 0, -1),
                        ]
                        .iter()
                        .any(|&(a, b, c)| !inside(x + a, y + b, z + c))
                    {
                        out.push(Vec3::new(x as f32, y as f32, z as f32));
                    }
                }
            }
        }
        out
    }

    #[test]
    fn voxel_surface_is_watertight() {
        let radius = 40.0;
        let pts = voxel_sphere(radius);
        let n = pts.len();
        let cloud = cloud_of(pts, vec![[1.0, 1.0, 1.0]; n]);
        // Several directions, some oblique, close enough that a voxel spans several pixels and far
        // enough that it spans less than one.
        for (eye, w) in [
            (DVec3::new(0.0, 0.0, 300.0), 256),
            (DVec3::new(170.0, 120.0, 190.0), 512),
            (DVec3::new(-900.0, 400.0, 50.0), 128),
        ] {
            let cam = camera(eye, DVec3::ZERO, w, w, 40.0);
            let img = render_cloud(&cloud, &cam, &ViewOptions::single_sample()).unwrap();
            // Every pixel whose ray meets a ball slightly smaller than the voxel hull must be covered.
            let mut inside = 0;
            for y in 0..w {
                for x in 0..w {
                    let ray = cam.ray(glam::DVec2::new(x as f64 + 0.5, y as f64 + 0.5));
                    let b = ray.origin.dot(ray.direction);
                    let c = ray.origin.length_squared() - (radius as f64 - 1.0).powi(2);
                    if b * b - c > 0.0 {
                        inside += 1;
                        assert_eq!(
                            img.alpha_at(x, y),
                            1.0,
                            "hole at ({x}, {y}) seen from {eye}"
                        );
                    }
                }
            }
            assert!(inside > 100, "the sphere covers {inside} pixels only");
        }
    }

    /// The nearest (depth, index) of every pixel by brute force: every cube against every pixel
    /// ray, in index order, nothing skipped, with the slab test's own arithmetic (the cubes lie
    /// well in front of the camera, so none is left out for reaching behind it).
    fn brute_force_z_buffer(points: &[Vec3], view: &ViewCamera, h: f32) -> Vec<Option<(u32, u32)>> {
        (0..view.height)
            .flat_map(|y| (0..view.width).map(move |x| (x, y)))
            .map(|(x, y)| {
                let d = view.world_ray(x, y);
                let inv = d.recip();
                let mut best: Option<(u32, u32)> = None;
                for (i, &p) in points.iter().enumerate() {
                    let rel = p - view.center;
                    let (t0, t1) = ((rel - h) * inv, (rel + h) * inv);
                    let near = t0.min(t1).max_element();
                    let far = t0.max(t1).min_element();
                    let key = (near.to_bits(), i as u32);
                    if near <= far && near > 0.0 && best.is_none_or(|b| key < b) {
                        best = Some(key);
                    }
                }
                best
            })
            .collect()
    }

    #[test]
    fn lane_cells_walk_the_rectangle_row_by_row() {
        for width in 1..=20 {
            for c in 0..width {
                let (dx, dy) = lane_cells(width, c);
                for l in 0..SLAB_LANES {
                    assert_eq!(
                        (dx[l] as usize, dy[l] as usize),
                        ((c + l) % width, (c + l) / width),
                        "width {width}, start {c}, lane {l}"
                    );
                }
            }
        }
    }

    #[test]
    fn skipped_cubes_could_not_have_won_a_pixel() {
        // Two voxel spheres, one behind the other and both with far sides, drawn nearest run
        // first with the runs and cubes behind what the z-buffer holds skipped: every pixel
        // keeps what testing every cube against every pixel gives. Cubes of one and of two
        // voxels, from views in front, oblique and from behind.
        let mut pts = voxel_sphere(9.0);
        pts.extend(
            voxel_sphere(7.0)
                .iter()
                .map(|p| *p + Vec3::new(6.0, 3.0, -30.0)),
        );
        // In Morton order, as the renderer draws a cloud, so that runs are patches of surface.
        let pts: Vec<Vec3> = plenoptic_io::morton_order(&pts)
            .iter()
            .map(|&i| pts[i as usize])
            .collect();
        // From in front and from behind the near side hides much of the far side.
        for (eye, h, far_side_hidden) in [
            (DVec3::new(0.0, 0.0, 90.0), 0.5, true),
            (DVec3::new(50.0, 30.0, 60.0), 1.0, false),
            (DVec3::new(-20.0, 10.0, -110.0), 0.5, true),
        ] {
            let cam = camera(eye, DVec3::new(2.0, 1.0, -12.0), 96, 96, 25.0);
            let view = ViewCamera::new(&cam).unwrap();
            let mut zbuf = ZBuffer::new(view.width as usize, view.height as usize);
            let hidden_runs = draw_cubes(&pts, &run_boxes(&pts), &view, h, &mut zbuf);
            // Runs of the far side are skipped whole, not cube by cube.
            assert!(
                hidden_runs > 0 || !far_side_hidden,
                "no run skipped whole from {eye}"
            );
            let expected = brute_force_z_buffer(&pts, &view, h);
            let mut covered = 0;
            for (pixel, want) in expected.iter().enumerate() {
                let (x, y) = (pixel % zbuf.width(), pixel / zbuf.width());
                let got = zbuf.get(x, y).map(|(z, id)| (z.to_bits(), id));
                assert_eq!(got, *want, "pixel {pixel} seen from {eye}");
                covered += usize::from(want.is_some());
            }
            assert!(
                covered > 1000,
                "the spheres cover {covered} pixels only from {eye}"
            );
        }
    }

    /// The bands follow the thread count (four, or one a thread): one, three and eight threads
    /// write the same z-buffer, spans included, from a view whose image is cut by the bands
    /// through the sphere.
    #[test]
    fn cube_pass_is_the_same_on_any_thread_count() {
        let pts = voxel_sphere(20.0);
        let runs = run_boxes(&pts);
        let cam = camera(DVec3::new(60.0, -40.0, 90.0), DVec3::ZERO, 157, 149, 35.0);
        let view = ViewCamera::new(&cam).unwrap();
        let (w, h) = (view.width as usize, view.height as usize);
        let draw = |threads: usize| {
            let pool = thread_pool(threads);
            let mut zbuf = ZBuffer::new(w, h);
            pool.install(|| draw_cubes(&pts, &runs, &view, 0.5, &mut zbuf));
            let cells: Vec<_> = (0..w * h).map(|p| zbuf.get(p % w, p / w)).collect();
            let spans: Vec<_> = (0..h).map(|y| zbuf.row_span(y)).collect();
            (cells, spans)
        };
        let one = draw(1);
        assert!(one.0.iter().filter(|c| c.is_some()).count() > 2000);
        assert_eq!(draw(3), one);
        assert_eq!(draw(8), one);
    }

    #[test]
    fn avx2_and_portable_cube_passes_write_the_same_z_buffer() {
        // A voxel sphere with a shifted, oblique camera (cubes straddling pixel centres, rays
        // near axis-parallel at the image's middle) and cubes larger than a pixel.
        let pts = voxel_sphere(30.0);
        for (eye, w, h) in [
            (DVec3::new(0.0, 0.0, 200.0), 200, 0.5),
            (DVec3::new(170.0, 120.0, 190.0), 331, 0.5),
            (DVec3::new(-90.0, 40.0, 50.0), 257, 1.7),
        ] {
            let cam = camera(eye, DVec3::new(0.3, -0.2, 0.1), w, w, 40.0);
            let view = ViewCamera::new(&cam).unwrap();
            let (width, height) = (view.width as usize, view.height as usize);
            let mut portable = ZBuffer::new(width, height);
            let mut vector = ZBuffer::new(width, height);
            let runs = run_boxes(&pts);
            draw_cubes_using(&pts, &runs, &view, h, &mut portable, false);
            draw_cubes_using(&pts, &runs, &view, h, &mut vector, has_avx2());
            let mut covered = 0;
            for pixel in 0..view.pixels() {
                let (x, y) = (pixel % width, pixel / width);
                let (a, b) = (portable.get(x, y), vector.get(x, y));
                assert_eq!(
                    a.map(|(z, id)| (z.to_bits(), id)),
                    b.map(|(z, id)| (z.to_bits(), id)),
                    "pixel {pixel} seen from {eye}"
                );
                covered += usize::from(a.is_some());
            }
            assert!(covered > 1000, "the sphere covers {covered} pixels only");
        }
    }

    #[test]
    fn single_point_renders_at_the_projected_pixel() {
        let cam = camera(
            DVec3::new(30.0, 20.0, 400.0),
            DVec3::new(3.0, -2.0, 1.0),
            640,
            480,
            20.0,
        );
        for p in [
            Vec3::new(3.3, -2.1, 1.7),
            Vec3::new(10.0, 5.0, -4.0),
            Vec3::new(-12.0, 9.0, 3.0),
        ] {
            let cloud = cloud_of(vec![p], vec![[0.2, 0.4, 0.6]]);
            // A tiny cube covers at most the one pixel whose centre is nearest its projection.
            let opts = ViewOptions {
                point_size: 0.05,
                ..ViewOptions::single_sample()
            };
            let uv = cam.project(p.as_dvec3()).unwrap();
            // Shift the point so its projection lands on a pixel centre, then check that pixel alone.
            let (px, py) = (uv.x.floor(), uv.y.floor());
            let target = glam::DVec2::new(px + 0.5, py + 0.5);
            let ray = cam.ray(target);
            let q = ray.at(cam.center().distance(p.as_dvec3()));
            let cloud = PlenopticCloud {
                positions: vec![q.as_vec3()],
                ..cloud
            };
            let img = render_cloud(&cloud, &cam, &opts).unwrap();
            let covered: Vec<(u32, u32)> = (0..480)
                .flat_map(|y| (0..640).map(move |x| (x, y)))
                .filter(|&(x, y)| img.alpha_at(x, y) > 0.0)
                .collect();
            assert_eq!(covered, vec![(px as u32, py as u32)]);
            assert_eq!(img.rgb_at(px as u32, py as u32), [0.2, 0.4, 0.6]);
            let depth = cam.depth(q) as f32;
            let d = img.depth_at(px as u32, py as u32);
            assert!((d - depth).abs() < 0.05, "depth {d} vs {depth}");
        }
    }

    #[test]
    fn point_seen_by_one_capture_camera_shows_its_colour() {
        // Three capture cameras 120° apart around the point; the viewer sits next to camera 1.
        let p = Vec3::new(10.0, 10.0, 10.0);
        let caps = [
            DVec3::new(1000.0, 10.0, 10.0),
            DVec3::new(10.0, 10.0, 1000.0),
            DVec3::new(-900.0, 10.0, -900.0),
        ];
        let colours = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let cloud = PlenopticCloud {
            positions: vec![p],
            colors: vec![[0.5, 0.5, 0.5]],
            num_cameras: 3,
            camera_colors: colours.to_vec(),
            cameras: caps
                .iter()
                .map(|&position| CaptureCamera {
                    position,
                    matrix: None,
                })
                .collect(),
            ..Default::default()
        };
        // Viewer exactly on camera 1's axis: camera 0 is at 90° (weight 0), camera 2 beyond.
        let cam = camera(DVec3::new(10.0, 10.0, 200.0), p.as_dvec3(), 64, 64, 20.0);
        let img = render_cloud(
            &cloud,
            &cam,
            &ViewOptions {
                point_size: 4.0,
                ..ViewOptions::single_sample()
            },
        )
        .unwrap();
        assert_eq!(img.rgb_at(32, 32), [0.0, 1.0, 0.0]);
        // From behind every camera the main colour shows.
        let cloud_front = PlenopticCloud {
            cameras: cloud.cameras[..2].to_vec(),
            num_cameras: 2,
            camera_colors: colours[..2].to_vec(),
            ..cloud.clone()
        };
        let back = camera(DVec3::new(-300.0, 10.0, -300.0), p.as_dvec3(), 64, 64, 20.0);
        let img = render_cloud(
            &cloud_front,
            &back,
            &ViewOptions {
                point_size: 4.0,
                ..ViewOptions::single_sample()
            },
        )
        .unwrap();
        assert_eq!(img.rgb_at(32, 32), [0.5, 0.5, 0.5]);
    }

    #[test]
    fn views_drawn_one_after_another_match_views_drawn_alone() {
        // A prepared cloud reuses one view's z-buffer, visible flags and colours for the next;
        // nothing of an earlier view (a nearer point, a colour, a visible flag) may show in a
        // later one, also when the view size changes in between. Colours vary with position,
        // so a colour left from another view would show.
        let pts = voxel_sphere(12.0);
        let colors = pts
            .iter()
            .map(|p| [0.5 + p.x / 30.0, 0.5 + p.y / 30.0, 0.5 + p.z / 30.0])
            .collect();
        let cloud = cloud_of(pts, colors);
        let opts = ViewOptions {
            point_size: 1.0,
            background: [0.1, 0.2, 0.3],
            ..ViewOptions::default()
        };
        let prepared = PreparedCloud::new(&cloud, &opts).unwrap();
        let views = [
            (DVec3::new(0.0, 0.0, 60.0), 48),
            (DVec3::new(50.0, 20.0, -30.0), 48),
            (DVec3::new(-20.0, -55.0, 10.0), 40),
            (DVec3::new(0.0, 30.0, 50.0), 48),
            (DVec3::new(0.0, 0.0, -60.0), 48),
        ];
        for (eye, w) in views {
            let cam = camera(eye, DVec3::ZERO, w, w, 40.0);
            let alone = render_cloud(&cloud, &cam, &opts).unwrap();
            let in_turn = prepared.render(&cam).unwrap();
            assert!(alone.alpha.iter().filter(|&&a| a > 0.0).count() > 100);
            assert_eq!(in_turn, alone, "view from {eye}");
        }
        // In parallel, several sets in flight and waiting at once, handed between views of
        // either size in any order.
        let pool = thread_pool(3);
        let cameras: Vec<_> = views
            .iter()
            .cycle()
            .take(15)
            .map(|&(eye, w)| camera(eye, DVec3::ZERO, w, w, 40.0))
            .collect();
        let alone: Vec<_> = cameras
            .iter()
            .map(|cam| render_cloud(&cloud, cam, &opts).unwrap())
            .collect();
        let in_parallel: Vec<_> = pool.install(|| {
            cameras
                .par_iter()
                .map(|cam| prepared.render(cam).unwrap())
                .collect()
        });
        assert_eq!(in_parallel, alone);
    }

    #[test]
    fn finished_views_leave_a_set_of_buffers_per_thread_at_most() {
        let pools = ViewBuffersPool::default();
        let threads = thread_pool(2);
        threads.install(|| {
            let sets: Vec<_> = (0..3).map(|_| pools.take(8, 8, 10)).collect();
            for set in sets {
                pools.give_back(set);
            }
        });
        assert_eq!(pools.waiting.lock().unwrap().len(), 2);
        // A waiting set is handed out again, cleared, before a new one is made.
        let mut set = pools.take(8, 8, 10);
        assert_eq!(pools.waiting.lock().unwrap().len(), 1);
        set.zbuf.insert(3, 3, 1.0, 7);
        assert_eq!(set.zbuf.get(3, 3), Some((1.0, 7)));
        *set.visible[4].get_mut() = true;
        pools.give_back(set);
        let again = pools.take(8, 8, 10);
        assert_eq!(again.zbuf.get(3, 3), None);
        assert!(!again.visible[4].load(Ordering::Relaxed));
    }

    #[test]
    fn no_buffers_wait_for_views_that_will_not_come() {
        let pools = ViewBuffersPool::default();
        pools.to_come.store(3, Ordering::Relaxed);
        let threads = thread_pool(4);
        threads.install(|| {
            // Two of three views start; one more is to come, so one finished set waits.
            let sets: Vec<_> = (0..2).map(|_| pools.take(8, 8, 10)).collect();
            for set in sets {
                pools.give_back(set);
            }
            assert_eq!(pools.waiting.lock().unwrap().len(), 1);
            // The last view takes it; none is to come, so its set is freed.
            let last = pools.take(8, 8, 10);
            assert!(pools.waiting.lock().unwrap().is_empty());
            pools.give_back(last);
            assert!(pools.waiting.lock().unwrap().is_empty());
            // More views than were announced still draw, keeping nothing.
            let extra = pools.take(8, 8, 10);
            pools.give_back(extra);
            assert!(pools.waiting.lock().unwrap().is_empty());
        });
    }

    #[test]
    fn nearer_point_wins_and_background_elsewhere() {
        let cam = camera(DVec3::new(0.0, 0.0, 100.0), DVec3::ZERO, 32, 32, 30.0);
        let cloud = cloud_of(
            vec![Vec3::new(0.0, 0.0, -5.0), Vec3::new(0.0, 0.0, 5.0)],
            vec![[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
        );
        let opts = ViewOptions {
            point_size: 4.0,
            background: [0.25, 0.5, 0.75],
            ..ViewOptions::single_sample()
        };
        let img = render_cloud(&cloud, &cam, &opts).unwrap();
        assert_eq!(img.rgb_at(16, 16), [0.0, 0.0, 1.0]);
        assert!(
            (img.depth_at(16, 16) - 93.0).abs() < 1e-3,
            "front face of the near cube at z = 93"
        );
        assert_eq!(img.rgb_at(0, 0), [0.25, 0.5, 0.75]);
        assert_eq!(img.alpha_at(0, 0), 0.0);
        assert_eq!(img.depth_at(0, 0), 0.0);
    }

    #[test]
    fn disc_covers_its_radius() {
        // fx = fy = f; a disc of radius ρ at depth z covers pixel centres within f·ρ/z of its centre.
        let cam = Camera::new(
            Intrinsics::centered(101, 101, 100.0, 100.0),
            Pose::look_at(DVec3::new(0.0, 0.0, 50.0), DVec3::ZERO, DVec3::Y),
        );
        let cloud = cloud_of(vec![Vec3::ZERO], vec![[1.0; 3]]);
        let opts = ViewOptions {
            point_shape: PointShape::Disc,
            point_size: 10.0,
            ..ViewOptions::single_sample()
        };
        let img = render_cloud(&cloud, &cam, &opts).unwrap();
        let r_px = 100.0 * disc_radius(10.0) / 50.0;
        for y in 0..101u32 {
            for x in 0..101u32 {
                let d = ((x as f32 + 0.5 - 50.5).powi(2) + (y as f32 + 0.5 - 50.5).powi(2)).sqrt();
                if (d - r_px).abs() > 1e-3 {
                    assert_eq!(
                        img.alpha_at(x, y) == 1.0,
                        d < r_px,
                        "pixel ({x}, {y}) at {d} px, radius {r_px}"
                    );
                }
            }
        }
    }

    #[test]
    fn supersampling_averages_coverage() {
        let cam = camera(DVec3::new(0.0, 0.0, 100.0), DVec3::ZERO, 16, 16, 30.0);
        let cloud = cloud_of(vec![Vec3::ZERO], vec![[1.0; 3]]);
        let opts = ViewOptions {
            point_size: 10.0,
            supersample: 4,
            ..ViewOptions::single_sample()
        };
        let img = render_cloud(&cloud, &cam, &opts).unwrap();
        assert_eq!((img.width, img.height), (16, 16));
        // Total coverage ≈ the cube face's projected area in pixels (front face at z = 95).
        let f = 8.0 / (15f32.to_radians().tan());
        let area = (f * 10.0 / 95.0).powi(2);
        let total: f32 = img.alpha.iter().sum();
        assert!(
            (total - area).abs() < 0.1 * area,
            "coverage {total} vs {area}"
        );
        assert!(img.alpha.iter().any(|&a| a > 0.0 && a < 1.0));
        for (i, &a) in img.alpha.iter().enumerate() {
            assert!(
                (img.rgb[3 * i] - a).abs() < 1e-6,
                "white on black equals coverage"
            );
        }
    }

    #[test]
    fn oversized_render_is_refused_before_allocating() {
        let cam = camera(
            DVec3::new(0.0, 0.0, 100.0),
            DVec3::ZERO,
            16_384,
            16_384,
            30.0,
        );
        let cloud = cloud_of(vec![Vec3::ZERO], vec![[1.0; 3]]);
        let err = render_cloud(&cloud, &cam, &ViewOptions::single_sample()).unwrap_err();
        assert!(matches!(err, Error::InvalidCamera(_)), "{err}");
        let small = camera(DVec3::new(0.0, 0.0, 100.0), DVec3::ZERO, 4096, 4096, 30.0);
        let opts = ViewOptions {
            supersample: 4,
            ..ViewOptions::single_sample()
        };
        assert!(matches!(
            render_cloud(&cloud, &small, &opts),
            Err(Error::InvalidCamera(_))
        ));
    }

    /// Points at the camera centre (in voxel coordinates, where its camera-space position is
    /// f32 rounding noise), inside a voxel around it, and a hair in front of it: with cubes and
    /// discs, supersampled or not, no pixel is NaN and the image is that of the other points
    /// alone, whose colours (viewer exactly at a capture camera's position too) are finite.
    #[test]
    fn points_at_the_camera_centre_are_not_drawn() {
        let eye = DVec3::new(812.3, 700.1, 1300.7);
        let target = DVec3::new(512.0, 500.0, 480.0);
        let cam = camera(eye, target, 48, 40, 30.0);
        let forward = (target - eye).normalize().as_vec3();
        let mut rng = 1_u32;
        let mut next = || {
            rng = rng.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (rng >> 8) as f32 / (1 << 24) as f32 - 0.5
        };
        let others: Vec<Vec3> = (0..200)
            .map(|_| target.as_vec3() + 60.0 * Vec3::new(next(), next(), next()))
            .collect();
        let e = eye.as_vec3();
        let near = [e, e + Vec3::new(0.3, -0.2, 0.1), e + 1e-3 * forward];
        let with_near: Vec<Vec3> = near.iter().chain(&others).copied().collect();
        let colours = |n: usize| -> Vec<[f32; 3]> {
            (0..n).map(|i| [0.1 + 0.004 * i as f32, 0.5, 0.9]).collect()
        };
        let rig = |n: usize| PlenopticCloud {
            colors: colours(n),
            num_cameras: 2,
            camera_colors: (0..2 * n).map(|i| [0.2, 0.001 * i as f32, 0.7]).collect(),
            // The viewer sits exactly on the first capture camera.
            cameras: [eye, DVec3::new(-400.0, 500.0, 480.0)]
                .iter()
                .map(|&position| CaptureCamera {
                    position,
                    matrix: None,
                })
                .collect(),
            ..Default::default()
        };
        for shape in [PointShape::Cube, PointShape::Disc] {
            for supersample in [1, 3] {
                let opts = ViewOptions {
                    point_shape: shape,
                    point_size: 4.0,
                    supersample,
                    ..ViewOptions::single_sample()
                };
                let mut a = rig(with_near.len());
                a.positions = with_near.clone();
                // Same per-point colours for the points both clouds share.
                let mut b = rig(others.len());
                b.positions = others.clone();
                b.colors = a.colors[near.len()..].to_vec();
                b.camera_colors = (0..others.len())
                    .flat_map(|i| a.camera_colors_of(i + near.len()).to_vec())
                    .collect();
                let img = render_cloud(&a, &cam, &opts).unwrap();
                let alone = render_cloud(&b, &cam, &opts).unwrap();
                for v in img.rgb.iter().chain(&img.alpha).chain(&img.depth) {
                    assert!(v.is_finite(), "{shape:?} ×{supersample}");
                }
                assert_eq!(img, alone, "{shape:?} ×{supersample}");
                assert!(img.alpha.iter().any(|&a| a > 0.0));
                // Without depth: the same colour and coverage, bit for bit.
                let no_depth = ViewOptions {
                    depth: false,
                    ..opts.clone()
                };
                let without = render_cloud(&a, &cam, &no_depth).unwrap();
                assert!(without.depth.is_empty() && img.depth.iter().any(|&z| z > 0.0));
                assert_eq!((without.rgb, without.alpha), (img.rgb, img.alpha));
            }
        }
    }

    #[test]
    fn inconsistent_cloud_is_refused() {
        let cam = camera(DVec3::new(0.0, 0.0, 100.0), DVec3::ZERO, 8, 8, 30.0);
        let cloud = cloud_of(vec![Vec3::ZERO, Vec3::ONE], vec![[1.0; 3]]);
        assert!(matches!(
            render_cloud(&cloud, &cam, &ViewOptions::single_sample()),
            Err(Error::InvalidModel(_))
        ));
    }
}
