//! The shading of a view's visible points: each point's colour towards the viewer
//! ([`interpolate_lanes_by`]), read from a copy of the cloud's colours in the order the cube pass
//! draws the points (Morton's), compact where the colours are 8-bit levels.

use glam::Vec3;
use plenoptic_io::PlenopticCloud;
use plenoptic_io::ply::uchar_color;
use plenoptic_io::view_color::interpolate_lanes_by;
#[cfg(target_arch = "x86_64")]
use plenoptic_io::view_color::interpolate8_avx2;
use rayon::prelude::*;

use crate::cpu::{prefetch, small_whole};

/// Points [`Shader::shade`] colours at once (one AVX2 vector of f32).
const SHADE_LANES: usize = plenoptic_io::view_color::AVX2_LANES;

/// How many points ahead [`Shader::shade`] asks for the colours it will read.
const PREFETCH_AHEAD: usize = 32;

/// Points per parallel work item of the copy.
const CHUNK: usize = 16_384;

/// The 256 colours an 8-bit channel stores, as a PLY file's uchar colours read.
fn levels() -> [f32; 256] {
    std::array::from_fn(|k| uchar_color(k as u8))
}

/// The 8-bit level of each of `values`, or `None` when one of them is not exactly a level.
fn to_levels(values: &[f32]) -> Option<Vec<u8>> {
    let mut out = vec![0u8; values.len()];
    let exact = out
        .par_chunks_mut(LEVEL_CHUNK)
        .zip(values.par_chunks(LEVEL_CHUNK))
        .all(|(out, values)| {
            // No early exit inside a chunk, so the loop vectorises.
            let mut exact = true;
            for (o, &v) in out.iter_mut().zip(values) {
                // The nearest level: v·255 clamped to [0, 255] (NaN to 0) and rounded in
                // vector lanes (`as u8` saturates and stayed scalar, a few nanoseconds a
                // value). A value that is a level rounds to it; any other fails the
                // comparison, whatever it rounds to.
                let x = v * 255.0;
                let x = if x > 0.0 { x } else { 0.0 };
                let x = if x < 255.0 { x } else { 255.0 };
                let k = small_whole(x) as u8;
                exact &= uchar_color(k).to_bits() == v.to_bits();
                *o = k;
            }
            exact
        });
    exact.then_some(out)
}

/// Values per parallel work item of [`to_levels`].
const LEVEL_CHUNK: usize = 1 << 16;

/// The cloud's main and per-camera colours of each point, by rank in the drawing order.
///
/// A view's visible points are the near side of the surface: whole runs of that order and
/// none of the far side. Read from the cloud's own arrays, in the file's order (a synthetic
/// frame's is random), each visible point's 13 per-camera colours were three cache lines on
/// their own in a 490 MB array, and the shading spent most of its time waiting for them
/// (docs/benchmarks/views.md, session 44). In the drawing order the visible points' colours
/// lie together; as 8-bit levels they take a quarter of the memory (122 MB at 8iVSLF's size).
pub(crate) struct ShadingColours {
    /// Per-camera colours of a point.
    cameras: usize,
    store: Store,
    /// The colour of each 8-bit level.
    levels: Box<[f32; 256]>,
}

enum Store {
    /// Every colour is an 8-bit level ([`levels`]): the level's index, 3 bytes a colour, the
    /// main colour first and then each camera's.
    Levels(Vec<u8>),
    /// Otherwise the colours themselves, in the same layout.
    Floats(Vec<[f32; 3]>),
}

impl ShadingColours {
    /// The colours of `cloud`'s points in `order` (rank → index in the cloud).
    pub(crate) fn new(cloud: &PlenopticCloud, order: &[u32]) -> Self {
        let cameras = cloud.num_cameras;
        let stride = 3 * (cameras + 1);
        // The levels of the cloud's colours in its own order first, read and written forwards
        // (taken in Morton order straight from the cloud's colours, each point's were three
        // cache lines of their own, and the copy cost as much as it saved), then moved into
        // Morton order a point's 42 bytes at a time.
        let main = to_levels(cloud.colors.as_flattened());
        let per_camera = to_levels(cloud.camera_colors.as_flattened());
        let store = match (main, per_camera) {
            (Some(main), Some(per_camera)) => {
                let mut bytes = vec![0u8; order.len() * stride];
                let camera_bytes = |i: usize| &per_camera[3 * cameras * i..3 * cameras * (i + 1)];
                bytes
                    .par_chunks_mut(stride * CHUNK)
                    .zip(order.par_chunks(CHUNK))
                    .for_each(|(out, ranks)| {
                        for (k, (out, &i)) in out.chunks_exact_mut(stride).zip(ranks).enumerate() {
                            // A synthetic frame's file order is random, so each point's levels
                            // are a cache miss of their own: ask for those of a later point.
                            if let Some(&ahead) = ranks.get(k + PREFETCH_AHEAD) {
                                prefetch(camera_bytes(ahead as usize));
                                prefetch(&main[3 * ahead as usize..3 * ahead as usize + 3]);
                            }
                            let i = i as usize;
                            let (head, tail) = out.split_at_mut(3);
                            head.copy_from_slice(&main[3 * i..3 * i + 3]);
                            tail.copy_from_slice(camera_bytes(i));
                        }
                    });
                Store::Levels(bytes)
            }
            _ => {
                let mut floats = vec![[0.0f32; 3]; order.len() * (cameras + 1)];
                floats
                    .par_chunks_mut(cameras + 1)
                    .zip(order.par_iter())
                    .with_min_len(CHUNK)
                    .for_each(|(out, &i)| {
                        let i = i as usize;
                        out[0] = cloud.colors[i];
                        out[1..].copy_from_slice(cloud.camera_colors_of(i));
                    });
                Store::Floats(floats)
            }
        };
        Self {
            cameras,
            store,
            levels: Box::new(levels()),
        }
    }

    /// Whether the colours are kept as 8-bit levels.
    #[cfg(test)]
    fn is_compact(&self) -> bool {
        matches!(self.store, Store::Levels(_))
    }

    /// Asks for the colours of rank `rank` to be loaded (see [`prefetch`]).
    #[inline(always)]
    fn prefetch(&self, rank: usize) {
        let stride = self.cameras + 1;
        match &self.store {
            Store::Levels(bytes) => {
                prefetch(&bytes[rank * stride * 3..(rank + 1) * stride * 3]);
            }
            Store::Floats(floats) => prefetch(&floats[rank * stride..(rank + 1) * stride]),
        }
    }

    /// Writes the colours of rank `rank` into lane `lane` of `main` and `per_camera` (one entry
    /// a capture camera, each channel's lanes together).
    #[inline(always)]
    fn read_lane<const N: usize>(
        &self,
        rank: usize,
        lane: usize,
        main: &mut [f32; 3],
        per_camera: &mut [[[f32; N]; 3]],
    ) {
        let stride = self.cameras + 1;
        match &self.store {
            Store::Levels(bytes) => {
                let levels = &self.levels;
                let bytes = &bytes[rank * stride * 3..(rank + 1) * stride * 3];
                *main = [0, 1, 2].map(|c| levels[bytes[c] as usize]);
                for (camera, b) in per_camera.iter_mut().zip(bytes[3..].chunks_exact(3)) {
                    for c in 0..3 {
                        camera[c][lane] = levels[b[c] as usize];
                    }
                }
            }
            Store::Floats(floats) => {
                let floats = &floats[rank * stride..(rank + 1) * stride];
                *main = floats[0];
                for (camera, f) in per_camera.iter_mut().zip(&floats[1..]) {
                    for c in 0..3 {
                        camera[c][lane] = f[c];
                    }
                }
            }
        }
    }

    /// Writes the colours of rank `rank` into `out` (`1 + cameras` long): the main colour,
    /// then each camera's.
    #[cfg(test)]
    fn read(&self, rank: usize, out: &mut [[f32; 3]]) {
        let mut per_camera = vec![[[0.0f32; 1]; 3]; self.cameras];
        self.read_lane(rank, 0, &mut out[0], &mut per_camera);
        for (o, camera) in out[1..].iter_mut().zip(&per_camera) {
            *o = camera.map(|[v]| v);
        }
    }
}

/// What the shading of one view's visible points shares.
pub(crate) struct Shader<'a> {
    /// The points' positions by rank.
    pub positions: &'a [Vec3],
    pub colours: &'a ShadingColours,
    /// Capture-camera positions.
    pub capture: &'a [Vec3],
    pub viewer: Vec3,
    pub exponent: i32,
}

impl Shader<'_> {
    /// Colours the points of ranks `ranks` (increasing) into `out`, [`SHADE_LANES`] at a time:
    /// the AVX2 kernel where the CPU has it, else the portable form (the same operations
    /// either way, so the same bits; `shading_colours_each_point_as_the_interpolation_does`).
    pub(crate) fn shade(&self, ranks: &[u32], out: &mut [[f32; 3]], avx2: bool) {
        #[cfg(target_arch = "x86_64")]
        if avx2 {
            // SAFETY: `avx2` is only true when `has_avx2()` is, so the CPU has AVX2.
            #[allow(unsafe_code)]
            return unsafe { self.shade_avx2(ranks, out) };
        }
        let _ = avx2;
        self.shade_portable(ranks, out);
    }

    /// The AVX2 interpolation ([`interpolate8_avx2`]) over the lanes.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn shade_avx2(&self, ranks: &[u32], out: &mut [[f32; 3]]) {
        self.shade_in_groups(ranks, out, |points, cameras, per_camera, main| {
            interpolate8_avx2(
                points,
                &[self.viewer; SHADE_LANES],
                cameras,
                per_camera,
                main,
                self.exponent,
            )
        });
    }

    fn shade_portable(&self, ranks: &[u32], out: &mut [[f32; 3]]) {
        self.shade_in_groups(ranks, out, |points, cameras, per_camera, main| {
            interpolate_lanes_by(
                *points,
                [self.viewer; SHADE_LANES],
                cameras,
                [cameras.len(); SHADE_LANES],
                |k, l| [0, 1, 2].map(|c| per_camera[k][c][l]),
                *main,
                self.exponent,
            )
        });
    }

    /// Reads the colours of [`SHADE_LANES`] points at a time and colours them with
    /// `interpolate(points, capture cameras, per-camera colours, main colours)`.
    #[inline(always)]
    fn shade_in_groups(
        &self,
        ranks: &[u32],
        out: &mut [[f32; 3]],
        interpolate: impl Fn(
            &[Vec3; SHADE_LANES],
            &[Vec3],
            &[[[f32; SHADE_LANES]; 3]],
            &[[f32; 3]; SHADE_LANES],
        ) -> [[f32; 3]; SHADE_LANES],
    ) {
        // Every point has a colour for each of these cameras.
        let cameras = &self.capture[..self.colours.cameras.min(self.capture.len())];
        // The lanes' colours as f32: each camera's, channel by channel, lane after lane, so
        // that the interpolation loads a camera's colours of all the lanes as vectors.
        let mut per_camera = vec![[[0.0f32; SHADE_LANES]; 3]; self.colours.cameras];
        let mut main = [[0.0f32; 3]; SHADE_LANES];
        for (g, (group, out)) in ranks
            .chunks(SHADE_LANES)
            .zip(out.chunks_mut(SHADE_LANES))
            .enumerate()
        {
            // The colours of the points PREFETCH_AHEAD places on are requested now, so they
            // are in the cache when their group comes (the visible points skip the far side).
            let ahead = (g * SHADE_LANES + PREFETCH_AHEAD..(g + 1) * SHADE_LANES + PREFETCH_AHEAD)
                .filter_map(|k| ranks.get(k));
            for &rank in ahead {
                self.colours.prefetch(rank as usize);
            }
            // A short last group repeats its first point in the spare lanes.
            let rank = |l: usize| *group.get(l).unwrap_or(&group[0]) as usize;
            for (l, main) in main.iter_mut().enumerate() {
                self.colours.read_lane(rank(l), l, main, &mut per_camera);
            }
            let points = std::array::from_fn(|l| self.positions[rank(l)]);
            let colours = interpolate(&points, cameras, &per_camera, &main);
            out.copy_from_slice(&colours[..out.len()]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(camera_colors: Vec<[f32; 3]>) -> PlenopticCloud {
        let n = camera_colors.len() / 2;
        PlenopticCloud {
            positions: (0..n).map(|i| Vec3::splat(i as f32)).collect(),
            colors: (0..n)
                .map(|i| [(i % 256) as f32 / 255.0, 0.0, 1.0])
                .collect(),
            num_cameras: 2,
            camera_colors,
            ..Default::default()
        }
    }

    #[test]
    fn colours_read_back_bit_for_bit_in_the_order_given() {
        // 8-bit levels (every level of a channel) are kept compact; a colour off the levels
        // keeps them all as floats. Either way each rank reads its point's colours exactly.
        let levels: Vec<[f32; 3]> = (0..512)
            .map(|i| {
                [
                    (i % 256) as f32 / 255.0,
                    ((i * 7) % 256) as f32 / 255.0,
                    1.0,
                ]
            })
            .collect();
        let mut floats = levels.clone();
        floats[77][1] = 0.123_456_7;
        for (camera_colors, compact) in [(levels, true), (floats, false)] {
            let cloud = cloud(camera_colors);
            let order: Vec<u32> = (0..cloud.len() as u32).rev().collect();
            let colours = ShadingColours::new(&cloud, &order);
            assert_eq!(colours.is_compact(), compact);
            let mut out = [[9.0f32; 3]; 3];
            for (rank, &i) in order.iter().enumerate() {
                colours.read(rank, &mut out);
                let i = i as usize;
                let want = [
                    cloud.colors[i],
                    cloud.camera_colors_of(i)[0],
                    cloud.camera_colors_of(i)[1],
                ];
                assert_eq!(
                    out.map(|c| c.map(f32::to_bits)),
                    want.map(|c| c.map(f32::to_bits)),
                    "rank {rank}"
                );
            }
        }
    }

    #[test]
    fn only_exact_levels_are_taken_as_levels() {
        // Every level is its own index, in chunks of several work items.
        let all: Vec<f32> = (0..3 * LEVEL_CHUNK + 17)
            .map(|i| uchar_color((i * 31 % 256) as u8))
            .collect();
        let want: Vec<u8> = (0..all.len()).map(|i| (i * 31 % 256) as u8).collect();
        assert_eq!(to_levels(&all), Some(want));
        // One value off the levels anywhere refuses them all: next to a level, between two,
        // outside [0, 1], negative zero, NaN of either sign, infinities.
        let level = uchar_color(200);
        for odd in [
            f32::from_bits(level.to_bits() + 1),
            f32::from_bits(level.to_bits() - 1),
            (uchar_color(3) + uchar_color(4)) * 0.5,
            1.0 + 1.0 / 255.0,
            -1.0 / 255.0,
            -0.0,
            f32::NAN,
            -f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ] {
            let mut values = all.clone();
            values[2 * LEVEL_CHUNK + 5] = odd;
            assert_eq!(to_levels(&values), None, "{odd} ({:#x})", odd.to_bits());
        }
    }

    /// Both instantiations of the shading colour every point as the one-lane interpolation
    /// does, bit for bit: 8-bit levels and floats, 13 cameras, a short last group.
    #[test]
    fn shading_colours_each_point_as_the_interpolation_does() {
        let cameras = 13;
        let n = 37;
        let capture: Vec<Vec3> = (0..cameras)
            .map(|i| {
                let a = i as f32 * 0.48;
                Vec3::new(a.cos() * 3000.0, (i % 3) as f32 * 400.0, a.sin() * 3000.0)
            })
            .collect();
        let level = |i: usize| uchar_color((i * 97 % 256) as u8);
        let mut camera_colors: Vec<[f32; 3]> = (0..n * cameras)
            .map(|i| [level(i), level(i + 1), level(3 * i)])
            .collect();
        let positions: Vec<Vec3> = (0..n)
            .map(|i| Vec3::new(i as f32 * 17.0, (i * i) as f32 % 300.0, 50.0 - i as f32))
            .collect();
        for compact in [true, false] {
            if !compact {
                camera_colors[5][1] = 0.123_456_7;
            }
            let cloud = PlenopticCloud {
                positions: positions.clone(),
                colors: (0..n).map(|i| [level(5 * i), level(2), level(i)]).collect(),
                num_cameras: cameras,
                camera_colors: camera_colors.clone(),
                ..Default::default()
            };
            // Ranks in a drawing order other than the file's.
            let order: Vec<u32> = (0..n as u32).rev().collect();
            let colours = ShadingColours::new(&cloud, &order);
            assert_eq!(colours.is_compact(), compact);
            let by_rank: Vec<Vec3> = order.iter().map(|&i| positions[i as usize]).collect();
            let shader = Shader {
                positions: &by_rank,
                colours: &colours,
                capture: &capture,
                viewer: Vec3::new(100.0, 2500.0, -800.0),
                exponent: 10,
            };
            let ranks: Vec<u32> = (0..n as u32).filter(|r| r % 5 != 2).collect();
            for avx2 in [false, crate::cpu::has_avx2()] {
                let mut out = vec![[0.0f32; 3]; ranks.len()];
                shader.shade(&ranks, &mut out, avx2);
                for (&rank, got) in ranks.iter().zip(&out) {
                    let i = order[rank as usize] as usize;
                    let want = plenoptic_io::view_color::interpolate(
                        positions[i],
                        shader.viewer,
                        &capture,
                        cloud.camera_colors_of(i),
                        cloud.colors[i],
                        10,
                    );
                    assert_eq!(
                        got.map(f32::to_bits),
                        want.map(f32::to_bits),
                        "rank {rank}, avx2 {avx2}, compact {compact}"
                    );
                }
            }
        }
    }
}
