//! `foldfree`: the command-line front end. It parses arguments, calls the library, prints, and
//! maps errors to exit codes (0 success, 2 bad input or usage, 1 any other failure; `param` and
//! `volmap` also 3: a fold-free map was written but the stop test was not met). One module per
//! subcommand; the developer tools are under `foldfree dev`.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod approx;
mod dev;
mod param;
mod render;
mod stats;
mod volmap;

#[derive(Parser)]
#[command(
    name = "foldfree",
    version,
    about = "Foldover-free, low-distortion maps of meshes (Vulkan compute + CPU f64)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Topology facts and the validation verdict of a mesh.
    Stats(stats::StatsArgs),
    /// UV-parameterize a mesh without flipped triangles (a disk, or any manifold mesh cut into
    /// charts).
    #[command(after_help = param::AFTER_HELP)]
    Param(Box<param::ParamArgs>),
    /// List the Vulkan devices and which one would be used.
    Devices,
    /// Render a UV-mapped OBJ (with `vt`) or glTF (a TEXCOORD set) textured with a checkerboard through its UVs, to PNG
    /// (offscreen Vulkan graphics).
    Render(render::RenderArgs),
    /// Approximate a triangle mesh by at most K planar polygons (Hu & Zhang 2017).
    Approx(approx::ApproxArgs),
    /// Foldover-free volumetric map of a tet mesh (Xu & Liu 2022).
    #[command(after_help = volmap::AFTER_HELP)]
    Volmap(Box<volmap::VolmapArgs>),
    /// Check a tet map against its rest mesh: inverted tets, δ_t, ρ (exit 1 if inverted).
    Volcheck(volmap::VolcheckArgs),
    /// Developer tools: benchmarks, test constraints, the default tuning file.
    #[command(subcommand)]
    Dev(dev::DevCommand),
}

/// `--max-faces` / `--max-tets`: 0 means no limit, for every command alike.
pub(crate) fn element_limit(n: usize) -> usize {
    if n == 0 {
        usize::MAX
    } else {
        n
    }
}

/// `--tuning FILE`: the file's solver knobs, or the defaults.
pub(crate) fn read_tuning(path: Option<&PathBuf>) -> foldfree::Result<foldfree::tuning::Tuning> {
    match path {
        Some(p) => foldfree::tuning::Tuning::from_file(p),
        None => Ok(Default::default()),
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Stats(args) => stats::run_stats(args),
        Command::Param(args) => param::run_param(*args),
        Command::Devices => stats::run_devices(),
        Command::Render(args) => render::run_render(args),
        Command::Approx(args) => approx::run_approx(args),
        Command::Volmap(args) => volmap::run_volmap(*args),
        Command::Volcheck(args) => volmap::run_volcheck(args),
        Command::Dev(cmd) => dev::run(cmd),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("foldfree: error: {e}");
            ExitCode::from(e.exit_code() as u8)
        }
    }
}
