//! The `wgsph` command line: parsing, the commands, and the exit codes. Nothing but the
//! executables (src/main.rs, and mpi/src/main.rs for `wgsph-mpi`) imports this floor; it
//! imports every other.

pub mod args;
pub mod bench;
pub mod compare;
pub mod errors;
pub mod first_run;
pub mod profile;
pub mod ranks;
pub mod resume;
pub mod run;
pub mod signals;
pub mod tradeoff;
pub mod validate;

use crate::model::builtin::BUILTIN_SCENES;
use args::{Cli, Command, ViewArgs};
use clap::Parser;
use errors::InputError;

/// Parses the command line, runs it and returns the process exit code:
/// 0 success, 1 a run that went bad or a failed check, 2 bad input, 130 / 143 a run stopped
/// by SIGINT / SIGTERM.
pub fn main() -> i32 {
    main_joining_ranks(None)
}

/// [`main`] for an executable that can join the ranks an MPI launcher started (`wgsph-mpi`).
pub fn main_joining_ranks(join: Option<ranks::Join>) -> i32 {
    quiet_wayland_probe();
    let cli = Cli::parse();
    // Output into a closed pipe (`wgsph run | head -1`) ends the process as it ends any Unix
    // tool, by SIGPIPE, instead of a panic in the next print; the files a run writes are
    // atomic, so none is left half-written. Not for the viewer, whose display connection is a
    // socket that may close under it.
    #[cfg(unix)]
    if !matches!(cli.command, Some(Command::View(_))) {
        // SAFETY: sets the disposition of one signal to its default before any thread starts.
        unsafe {
            libc::signal(libc::SIGPIPE, libc::SIG_DFL);
        }
    }
    let quiet = matches!(&cli.command, Some(Command::Run(a)) if a.quiet);
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or(if quiet { "error" } else { "warn" })).init();
    let result = match cli.command {
        None => first_run::cmd_first_run(),
        Some(command) => run_command(command, join),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            errors::exit_code(&e)
        }
    }
}

/// wgpu's OpenGL backend loads libwayland to look for a Wayland display, and libwayland prints
/// "error: XDG_RUNTIME_DIR is invalid or not set in the environment" on machines without a
/// desktop session (servers, containers, CI): on a first run that reads as if wgsph had failed.
/// Without a runtime directory no Wayland display can be found anyway, so a private empty one
/// (mode 0700, as libwayland requires) changes nothing but the noise. Runs before any thread.
#[cfg(unix)]
fn quiet_wayland_probe() {
    use std::os::unix::fs::{DirBuilderExt, MetadataExt};
    if std::env::var_os("XDG_RUNTIME_DIR").is_some() || std::env::var_os("WAYLAND_DISPLAY").is_some() {
        return;
    }
    // SAFETY: geteuid has no preconditions and cannot fail.
    let uid = unsafe { libc::geteuid() };
    let dir = std::env::temp_dir().join(format!("wgsph-runtime-{uid}"));
    let _ = std::fs::DirBuilder::new().mode(0o700).create(&dir);
    match std::fs::symlink_metadata(&dir) {
        // Only a directory of this user's that no one else can reach, as libwayland checks.
        Ok(m) if m.is_dir() && m.uid() == uid && m.mode() & 0o777 == 0o700 => std::env::set_var("XDG_RUNTIME_DIR", &dir),
        _ => {}
    }
}

#[cfg(not(unix))]
fn quiet_wayland_probe() {}

fn run_command(command: Command, join: Option<ranks::Join>) -> anyhow::Result<i32> {
    let name = match &command {
        Command::Run(_) => "run",
        Command::Compare(_) => "compare",
        Command::View(_) => "view",
        Command::Tradeoff(_) => "tradeoff",
        Command::Validate(_) => "validate",
        Command::Profile(_) => "profile",
        Command::Bench(_) => "bench",
        Command::Adapters => "adapters",
        Command::Scenes => "scenes",
    };
    let ranks = ranks::start(name, join)?;
    match command {
        Command::Run(args) => ranks::run_as_rank(ranks, |ranks| match &args.resume {
            Some(dir) => resume::resume_run(dir, &args, ranks),
            None => run::cmd_run(&args, ranks),
        }),
        Command::Compare(args) => compare::cmd_compare(&args),
        Command::View(args) => cmd_view(&args),
        Command::Tradeoff(args) => tradeoff::cmd_tradeoff(&args),
        Command::Validate(args) => validate::cmd_validate(&args),
        Command::Profile(args) => profile::cmd_profile(&args),
        Command::Bench(args) => bench::cmd_bench(&args),
        Command::Adapters => {
            let lines = crate::solver::gpu::device::describe_adapters();
            if lines.is_empty() {
                println!("no GPU adapter found");
            }
            for l in lines {
                println!("{l}");
            }
            Ok(0)
        }
        Command::Scenes => {
            for (name, description, _) in BUILTIN_SCENES {
                println!("{name:<12} {description}");
            }
            println!("(a SCENE may also be a wgsph TOML file, or a SPlisHSPlasH JSON scene: docs/scenes.md;");
            println!(" the repository's scenes/ folder holds these, dam_break_pier.toml, walls read from a mesh file,");
            println!(" and weightless_cube.toml, water held together by surface tension)");
            Ok(0)
        }
    }
}

#[cfg(feature = "view")]
fn cmd_view(args: &ViewArgs) -> anyhow::Result<i32> {
    if args.picture.style == Some(crate::viz::render::Style::Mesh) {
        return Err(InputError("--style mesh is for `wgsph run --frames` (the surface is reconstructed on the host, too slowly for a window); `wgsph view` takes --style particles or surface".into()).into());
    }
    let scene = args::load_scene(&args.scene, &args.overrides, args.particles, false)?;
    if let Some(path) = &args.screenshot {
        check_screenshot_path(path)?;
    }
    // No display is an environment that cannot run the command, as no adapter is: exit 2.
    if cfg!(all(unix, not(target_os = "macos"))) && ["DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"].iter().all(|v| std::env::var_os(v).is_none()) {
        return Err(InputError("cannot open a window: no display (set DISPLAY or WAYLAND_DISPLAY; on a headless machine run under Xvfb, see docs/pictures.md)".into()).into());
    }
    let dt = scene.time.dt;
    let steps_per_frame = args.steps_per_frame.unwrap_or_else(|| ((1.0 / 60.0 / dt).ceil() as u64).clamp(1, 64));
    crate::viz::view::view(
        scene,
        crate::viz::view::ViewOptions {
            picture: args.picture.options(),
            steps_per_frame,
            screenshot: args.screenshot.clone(),
            quit_after: args.quit_after,
        },
    )
}

/// The screenshot's path, checked before the window opens: a new file (a PNG carries no mark
/// of who wrote it, so an existing file is never replaced) in an existing directory.
#[cfg(feature = "view")]
fn check_screenshot_path(path: &std::path::Path) -> Result<(), InputError> {
    let bad = |why: &str| InputError(format!("--screenshot {}: {why}; allowed: the path of a new file in an existing directory", path.display()));
    if path.is_dir() {
        return Err(bad("is a directory"));
    }
    if std::fs::symlink_metadata(path).is_ok() {
        return Err(bad("exists, and wgsph replaces only its own output: remove it, or choose another name"));
    }
    let parent = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(std::path::Path::new("."));
    if !parent.is_dir() {
        return Err(bad(&format!("{} is not a directory", parent.display())));
    }
    Ok(())
}

#[cfg(not(feature = "view"))]
fn cmd_view(_: &ViewArgs) -> anyhow::Result<i32> {
    Err(InputError("this wgsph was built without the `view` feature (a headless build); rebuild with default features for `wgsph view`".into()).into())
}

