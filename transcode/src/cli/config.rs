//! `transcode config`: print the default configuration or check a file; and the command-line
//! overrides every pipeline subcommand shares.

use std::path::{Path, PathBuf};

use transcode::config::{Config, InitMode, Sampling, ShDegree};

/// Arguments of `transcode config`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Print the default configuration as TOML.
    #[arg(long, conflicts_with = "check")]
    defaults: bool,
    /// Check a TOML configuration file and print it with every default filled in.
    #[arg(long, value_name = "FILE")]
    check: Option<PathBuf>,
}

/// Runs `transcode config`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let config = match &args.check {
        Some(path) => Config::load(path).map_err(flat)?,
        None if args.defaults => Config::default(),
        None => {
            anyhow::bail!("say --defaults to print the defaults or --check FILE to check a file")
        }
    };
    print!("{}", config.to_toml());
    Ok(())
}

/// The configuration file and every flag that overrides it, for the commands that run the
/// pipeline (run, demo, sequence). `views` takes the file and the rig's flags only, `eval` the
/// file only: a flag a command would ignore is not offered (clap refuses it).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct Overrides {
    #[command(flatten)]
    pub file: ConfigFile,
    #[command(flatten)]
    pub rig: RigFlags,
    #[command(flatten)]
    pub pipeline: PipelineFlags,
}

impl Overrides {
    /// The configuration: `base` (or the `--config` file) with the flags applied, validated.
    pub fn resolve(&self, base: Config) -> anyhow::Result<Config> {
        let mut c = self.file.load(base)?;
        self.rig.apply(&mut c);
        self.pipeline.apply(&mut c);
        validated(c)
    }
}

/// The `--config` file, over a command's defaults.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ConfigFile {
    /// TOML configuration file (see `transcode config --defaults`); flags override it.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
}

impl ConfigFile {
    /// `base`, or the `--config` file read over it (not yet validated).
    pub fn load(&self, base: Config) -> anyhow::Result<Config> {
        match &self.config {
            Some(path) => Config::load_over(path, &base).map_err(flat),
            None => Ok(base),
        }
    }

    /// [`ConfigFile::load`] validated: for a command no flag overrides.
    pub fn resolve(&self, base: Config) -> anyhow::Result<Config> {
        self.load(base).and_then(validated)
    }
}

/// The flags that place the training cameras and size their views (`rig.*`).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct RigFlags {
    /// Training cameras on the Fibonacci sphere.
    #[arg(long)]
    pub cameras: Option<usize>,
    /// Image size of every view, e.g. 512 or 640x480.
    #[arg(long, value_name = "W[xH]", value_parser = parse_resolution)]
    pub resolution: Option<(u32, u32)>,
    /// Vertical field of view in degrees.
    #[arg(long, value_name = "DEG")]
    pub fov: Option<f64>,
}

impl RigFlags {
    /// Applies the flags given to `c`.
    pub fn apply(&self, c: &mut Config) {
        if let Some(v) = self.cameras {
            c.rig.cameras = v;
        }
        if let Some((w, h)) = self.resolution {
            c.rig.width = w;
            c.rig.height = h;
        }
        if let Some(v) = self.fov {
            c.rig.fov_y_deg = v;
        }
    }
}

/// A configuration the flags were applied to, checked, with the check's error saying so.
pub fn validated(c: Config) -> anyhow::Result<Config> {
    c.validate()
        .map_err(|e| anyhow::anyhow!("{e} (after applying the command-line flags)"))?;
    Ok(c)
}

/// The flags of the held-out views, the splats, their training and the files written.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct PipelineFlags {
    /// Held-out cameras for evaluation.
    #[arg(long)]
    pub heldout: Option<usize>,
    /// Initialisation: surface or sparse.
    #[arg(long, value_parser = parse_init)]
    pub init: Option<InitMode>,
    /// Splats: `auto` (the default: start from the input's points, merged to about two per
    /// covered pixel of the mean training view, and prune by contribution while held-out PSNR
    /// stays within `--budget-tolerance` of the whole model), `all` (one per input point, no
    /// pruning), or a number K, a hard cap: start as `auto` does but from at most about K points,
    /// and let the automatic budget prune below that (add `--no-prune` for about K exactly).
    #[arg(long, value_name = "auto|all|K")]
    pub splats: Option<SplatCount>,
    /// The held-out PSNR (dB) the automatic splat budget may give up against the whole model.
    #[arg(long, value_name = "DB")]
    pub budget_tolerance: Option<f64>,
    /// Keep every initial splat (no automatic pruning).
    #[arg(long)]
    pub no_prune: bool,
    /// How the K points are chosen: voxel or farthest.
    #[arg(long, value_parser = parse_sampling)]
    pub sampling: Option<Sampling>,
    /// Sparse init from this COLMAP model folder's points3D.
    #[arg(long, value_name = "DIR")]
    pub points3d: Option<PathBuf>,
    /// SH degree 0..3 or auto.
    #[arg(long, value_name = "0..3|auto")]
    pub sh_degree: Option<ShDegree>,
    /// Training iterations.
    #[arg(long)]
    pub iterations: Option<u32>,
    /// Training time budget in seconds: the wall time from the speed probe to the last step,
    /// the splat budget's rounds and the checkpoints included (the schedule is fitted to it).
    #[arg(long, value_name = "SECONDS", value_parser = parse_budget_seconds)]
    pub time_budget: Option<f64>,
    /// Score the held-out views every K training steps for the report's held-out curve.
    #[arg(long, value_name = "K")]
    pub eval_every: Option<u32>,
    /// Random seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Keep surface splats on the input's points (by default they move, and merged splats
    /// find their place).
    #[arg(long)]
    pub fixed_positions: bool,
    /// Densify surface splats too.
    #[arg(long)]
    pub densify: bool,
    /// Also write the model as a .splat file.
    #[arg(long)]
    pub splat_file: bool,
    /// Do not write the models as SPZ (written by default beside each PLY).
    #[arg(long)]
    pub no_spz: bool,
    /// Do not write the COLMAP dataset of the training views (rendered in memory only; the
    /// model is the same). Saves most of a frame's disk in long sequences.
    #[arg(long)]
    pub no_dataset: bool,
    /// Also write the models as binary glTF with KHR_gaussian_splatting (.glb).
    #[arg(long)]
    pub glb: bool,
    /// Also train from the other init mode and compare both in the report.
    #[arg(long)]
    pub compare_init: bool,
    /// Train with the antialiased (Mip-Splatting) opacity compensation
    /// (`training.antialiased`): sharper silhouettes (the README demo gains about 2.5 dB of
    /// held-out PSNR on black and 3 dB on white), at the price of more splats from the
    /// automatic budget; the PLY says so in a header comment
    /// (`SplatRenderMode: mip`) and the SPZ in its flag, which Brush, PlayCanvas / SuperSplat,
    /// splat-transform and our viewer read, but a viewer that ignores them draws it too opaque.
    #[arg(long)]
    pub antialiased: bool,
}

impl PipelineFlags {
    /// Applies the flags given to `c`.
    pub fn apply(&self, c: &mut Config) {
        let o = self;
        if let Some(v) = o.heldout {
            c.rig.heldout_cameras = v;
        }
        if let Some(v) = o.init {
            c.init.mode = v;
        }
        match o.splats {
            Some(SplatCount::Auto) => {
                c.init.splats = None;
                c.budget.auto = true;
            }
            Some(SplatCount::All) => {
                c.init.splats = None;
                c.budget.auto = false;
            }
            Some(SplatCount::Count(k)) => c.init.splats = Some(k),
            None => {}
        }
        if let Some(v) = o.budget_tolerance {
            c.budget.tolerance_db = v;
        }
        if o.no_prune {
            c.budget.auto = false;
        }
        if let Some(v) = o.sampling {
            c.init.sampling = v;
        }
        if o.points3d.is_some() {
            c.init.points3d.clone_from(&o.points3d);
        }
        if let Some(v) = o.sh_degree {
            c.init.sh_degree = v;
        }
        if let Some(v) = o.iterations {
            c.training.iterations = v;
        }
        if let Some(v) = o.eval_every {
            c.eval.every = v;
        }
        if o.time_budget.is_some() {
            c.training.time_budget_s = o.time_budget;
        }
        if let Some(v) = o.seed {
            c.training.seed = v;
        }
        c.init.free_positions &= !o.fixed_positions;
        c.init.densify_surface |= o.densify;
        c.output.splat_file |= o.splat_file;
        c.output.spz &= !o.no_spz;
        c.output.dataset &= !o.no_dataset;
        c.output.glb |= o.glb;
        c.output.compare_init |= o.compare_init;
        // A flag only turns a setting on, so the file's `true` stays.
        c.training.antialiased |= o.antialiased;
    }
}

/// One-line error from a library error whose message already includes its causes (so that the
/// `{:#}` chain printed by `main` does not repeat them).
pub fn flat(err: impl std::fmt::Display) -> anyhow::Error {
    anyhow::anyhow!("{err}")
}

/// Fails with a clear message when `path` does not exist.
pub fn require_file(path: &Path, what: &str) -> anyhow::Result<()> {
    if !path.exists() {
        anyhow::bail!("{what} {} does not exist", path.display());
    }
    Ok(())
}

/// A time budget in seconds (`--time-budget`): finite, positive, at most
/// [`transcode::config::MAX_SECONDS`].
pub fn parse_budget_seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    transcode::config::check_seconds(v, false).map(|()| v)
}

/// An interval in seconds (`--checkpoint-interval`): finite, at least 0, at most
/// [`transcode::config::MAX_SECONDS`].
pub fn parse_interval_seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    transcode::config::check_seconds(v, true).map(|()| v)
}

fn parse_resolution(s: &str) -> Result<(u32, u32), String> {
    let bad = || format!("resolution must be W or WxH with positive integers, got {s:?}");
    let (w, h) = match s.split_once(['x', 'X']) {
        Some((w, h)) => (w.parse().map_err(|_| bad())?, h.parse().map_err(|_| bad())?),
        None => {
            let w = s.parse().map_err(|_| bad())?;
            (w, w)
        }
    };
    if w == 0 || h == 0 {
        return Err(bad());
    }
    Ok((w, h))
}

fn parse_init(s: &str) -> Result<InitMode, String> {
    match s {
        "surface" => Ok(InitMode::Surface),
        "sparse" => Ok(InitMode::Sparse),
        _ => Err(format!("init must be surface or sparse, got {s:?}")),
    }
}

fn parse_sampling(s: &str) -> Result<Sampling, String> {
    match s {
        "voxel" => Ok(Sampling::Voxel),
        "farthest" => Ok(Sampling::Farthest),
        _ => Err(format!("sampling must be voxel or farthest, got {s:?}")),
    }
}

/// The value of `--splats`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SplatCount {
    /// The automatic budget.
    Auto,
    /// One splat per input point, no pruning.
    All,
    /// At most about K initial splats (fewer where the automatic budget starts lower), pruned
    /// below that by the automatic budget unless `--no-prune` (then about K).
    Count(usize),
}

impl std::str::FromStr for SplatCount {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "auto" => Ok(Self::Auto),
            "all" => Ok(Self::All),
            _ => match s.parse::<usize>() {
                Ok(k) if k >= splat_init::config::MIN_SPLATS => Ok(Self::Count(k)),
                _ => Err(format!(
                    "expected auto, all or a number of splats of at least {}, got {s:?}",
                    splat_init::config::MIN_SPLATS
                )),
            },
        }
    }
}
