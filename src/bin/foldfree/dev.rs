//! `foldfree dev …`: developer tools — the benchmark table and device profile, the twist
//! constraints of the volumetric tests, and the default tuning file.

use std::path::PathBuf;

use clap::Subcommand;
use foldfree::files::{Outputs, DEFAULT_MAX_ELEMENTS};
use foldfree::param::{BackendChoice, Energy};

use crate::element_limit;

#[derive(Subcommand)]
pub enum DevCommand {
    /// Time `param` over meshes, energies and backends; prints a Markdown table.
    Bench {
        /// Input surface files, OBJ, PLY, OFF or STL (disk topology).
        meshes: Vec<PathBuf>,
        /// Energies to run (mips, sd).
        #[arg(long, value_enum, num_args = 1.., default_values = ["mips", "sd"])]
        energy: Vec<Energy>,
        /// Backends to run (cpu, vulkan, auto).
        #[arg(long, value_enum, num_args = 1.., default_values = ["cpu", "vulkan"])]
        backend: Vec<BackendChoice>,
        #[arg(long)]
        max_iters: Option<usize>,
        /// Directory for the output meshes.
        #[arg(long, default_value = "target/bench-out")]
        out_dir: PathBuf,
        /// Device profile instead: per-kernel timestamps of the ADMM iteration (`--max-iters`
        /// iterations, default 200), bytes and bandwidth against the device's streaming rate,
        /// dispatch overhead, and `param` end to end on Vulkan vs CPU (benches/gpu_profile.sh).
        #[arg(long)]
        profile: bool,
    },
    /// Write a constraints file (`vertex x y z`) twisting part of a tet mesh's boundary.
    VolmapConstraints(VolConstraintArgs),
    /// Print the default tuning file (every key of `--tuning`, with its default) as TOML.
    Tuning,
}

#[derive(clap::Args)]
pub struct VolConstraintArgs {
    /// Rest tet mesh.
    rest: PathBuf,
    /// Output constraints file.
    #[arg(short, long)]
    output: PathBuf,
    /// Twist angle (degrees) of the far end about the longest bounding-box axis.
    #[arg(long, default_value_t = 60.0, allow_hyphen_values = true)]
    twist: f64,
    /// Fraction of the length held at each end (near end fixed, far end twisted).
    #[arg(long, default_value_t = 0.15)]
    fraction: f64,
    /// Refuse meshes with more tets (and files larger than such a mesh's text); 0 = no limit.
    #[arg(long, default_value_t = DEFAULT_MAX_ELEMENTS)]
    max_tets: usize,
}

pub fn run(cmd: DevCommand) -> foldfree::Result<()> {
    match cmd {
        DevCommand::Bench {
            meshes,
            max_iters,
            out_dir,
            profile: true,
            ..
        } => run_profile(meshes, max_iters, out_dir),
        DevCommand::Bench {
            meshes,
            energy,
            backend,
            max_iters,
            out_dir,
            profile: false,
        } => run_bench(meshes, energy, backend, max_iters, out_dir),
        DevCommand::VolmapConstraints(args) => run_volmap_constraints(args),
        DevCommand::Tuning => {
            print!("{}", foldfree::tuning::Tuning::default_toml());
            Ok(())
        }
    }
}

fn run_volmap_constraints(a: VolConstraintArgs) -> foldfree::Result<()> {
    use foldfree::vol::constraints::{constraints_text, twist_constraints};
    let mut outputs = Outputs::new();
    foldfree::vol::tetgen::tet_input(&mut outputs, &a.rest);
    outputs.output(&a.output, "constraints", &[])?;
    foldfree::vol::constraints::check_twist(a.twist, a.fraction)?;
    let rest = foldfree::vol::job::read_rest(&a.rest, element_limit(a.max_tets))?;
    let c = twist_constraints(&rest, a.twist, a.fraction);
    let header = format!(
        "foldfree dev volmap-constraints {} --twist {} --fraction {}\nvertex_index x y z (0-based)",
        a.rest.display(),
        a.twist,
        a.fraction
    );
    outputs.set(&a.output, constraints_text(&c, &header).into_bytes());
    outputs.commit()?;
    eprintln!(
        "wrote {} ({} constrained vertices)",
        a.output.display(),
        c.len()
    );
    Ok(())
}

fn run_bench(
    meshes: Vec<PathBuf>,
    energy: Vec<Energy>,
    backend: Vec<BackendChoice>,
    max_iters: Option<usize>,
    out_dir: PathBuf,
) -> foldfree::Result<()> {
    if meshes.is_empty() {
        return Err(foldfree::Error::Usage(
            "dev bench needs at least one mesh".into(),
        ));
    }
    let job = foldfree::bench::BenchJob {
        meshes,
        energies: energy,
        backends: backend,
        max_iters,
        out_dir,
    };
    if job.backends.contains(&BackendChoice::Vulkan) {
        let ctx = foldfree::gpu::Context::new(&foldfree::gpu::ContextDesc::default())?;
        let gbs = foldfree::bench::device_bandwidth(&ctx, 1 << 24, 5)?;
        println!(
            "device: {} — measured bandwidth (saxpy, 16M floats, best of 5): {gbs:.2} GB/s\n",
            ctx.device_name()
        );
    }
    let out = foldfree::bench::run_bench(&job, |line| eprintln!("{line}"))?;
    println!("{}", out.table);
    // A failed run is in the table, and its error decides the exit code.
    out.first_error.map_or(Ok(()), Err)
}

fn run_profile(
    meshes: Vec<PathBuf>,
    max_iters: Option<usize>,
    out_dir: PathBuf,
) -> foldfree::Result<()> {
    if meshes.is_empty() {
        return Err(foldfree::Error::Usage(
            "dev bench --profile needs at least one mesh".into(),
        ));
    }
    std::fs::create_dir_all(&out_dir).map_err(|source| foldfree::Error::Io {
        path: out_dir.clone(),
        source,
    })?;
    let ctx = foldfree::gpu::Context::new(&foldfree::gpu::ContextDesc::default())?;
    for mesh in &meshes {
        eprintln!("profiling {} …", mesh.display());
        let p = foldfree::bench::profile_mesh(&ctx, mesh, max_iters.unwrap_or(200), &out_dir)?;
        println!("{}", p.table());
    }
    Ok(())
}
