//! `wgsph view` in a real window on a virtual X server (Xvfb), on each backend that can draw
//! there: the picture it presents is not blank, and the X server's own screen shows it.
//! Skipped with a message where Xvfb is missing, unless WGSPH_REQUIRE_XVFB is set (CI sets it).
#![cfg(feature = "view")]

use crate::common;

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

struct Xvfb {
    child: Child,
    display: String,
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn on_path(program: &str) -> bool {
    std::env::var_os("PATH").is_some_and(|paths| std::env::split_paths(&paths).any(|d| d.join(program).is_file()))
}

/// Starts Xvfb on a free display, or None (with a message) where it is not installed.
fn xvfb() -> Option<Xvfb> {
    if !on_path("Xvfb") {
        if std::env::var_os("WGSPH_REQUIRE_XVFB").is_some() {
            panic!("WGSPH_REQUIRE_XVFB is set but Xvfb is not installed");
        }
        eprintln!("SKIPPED: Xvfb is not installed (apt-get install -y xvfb)");
        return None;
    }
    // -displayfd: Xvfb picks a free display and writes its number to stdout when ready.
    let mut child = Command::new("Xvfb")
        .args(["-displayfd", "1", "-screen", "0", "800x600x24", "-nolisten", "tcp"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("Xvfb starts");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
    let n: u32 = line.trim().parse().unwrap_or_else(|_| panic!("Xvfb did not report a display: '{line}'"));
    Some(Xvfb { child, display: format!(":{n}") })
}

fn view(display: &str, backend: &str, args: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_wgsph"));
    c.arg("view").args(args).env("DISPLAY", display).env_remove("WAYLAND_DISPLAY").env("WGPU_BACKEND", backend);
    c
}

/// Backends with a compute adapter here.
fn backends() -> Vec<&'static str> {
    let mut out = Vec::new();
    for ctx in common::contexts() {
        let b = match ctx.info.backend {
            wgpu::Backend::Vulkan => "vulkan",
            wgpu::Backend::Gl => "gl",
            wgpu::Backend::Metal => "metal",
            wgpu::Backend::Dx12 => "dx12",
            _ => continue,
        };
        if !out.contains(&b) {
            out.push(b);
        }
    }
    out
}

/// Distinct colours in an RGBA picture.
fn colours(rgba: &[u8]) -> usize {
    let mut set: Vec<[u8; 3]> = rgba.chunks_exact(4).map(|p| [p[0], p[1], p[2]]).collect();
    set.sort();
    set.dedup();
    set.len()
}

#[test]
fn view_presents_a_picture_of_the_simulation() {
    let Some(x) = xvfb() else { return };
    for backend in backends() {
        let dir = tempfile::tempdir().unwrap();
        let shot = dir.path().join("shot.png");
        let out = view(&x.display, backend, &["hydrostatic", "--resolution", "320x240", "--quit-after", "5", "--screenshot", shot.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(out.status.success(), "{backend}: {}", String::from_utf8_lossy(&out.stderr));
        let img = image::open(&shot).unwrap().to_rgba8();
        assert_eq!(img.dimensions(), (320, 240), "{backend}");
        let n = colours(img.as_raw());
        assert!(n > 50, "{backend}: the screenshot has only {n} colours");
    }
}

/// Reads a ZPixmap XWD dump of 24/32-bit TrueColor (what `xwd -root` gives on Xvfb's 24-bit
/// screen) into RGBA.
fn read_xwd(bytes: &[u8]) -> (u32, u32, Vec<u8>) {
    let word = |i: usize| u32::from_be_bytes(bytes[4 * i..4 * i + 4].try_into().unwrap());
    let (header, width, height, byte_order, bpp, line) = (word(0), word(4), word(5), word(7), word(11), word(12));
    let ncolors = word(19);
    assert_eq!(bpp, 32, "xwd: {bpp} bits per pixel");
    let data = &bytes[(header + 12 * ncolors) as usize..];
    let mut rgba = Vec::with_capacity((width * height * 4) as usize);
    for y in 0..height as usize {
        for x in 0..width as usize {
            let p = &data[y * line as usize + 4 * x..][..4];
            let v = if byte_order == 0 { u32::from_le_bytes(p.try_into().unwrap()) } else { u32::from_be_bytes(p.try_into().unwrap()) };
            rgba.extend_from_slice(&[(v >> 16) as u8, (v >> 8) as u8, v as u8, 255]);
        }
    }
    (width, height, rgba)
}

#[test]
fn the_x_server_shows_the_window() {
    let Some(x) = xvfb() else { return };
    if !on_path("xwd") {
        eprintln!("SKIPPED: xwd is not installed (apt-get install -y x11-apps)");
        return;
    }
    for backend in backends() {
        let mut child = view(&x.display, backend, &["hydrostatic", "--resolution", "400x300"]).stdout(Stdio::piped()).spawn().unwrap();
        let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
        let drawing = lines.by_ref().map_while(Result::ok).any(|l| l.starts_with("drawing on"));
        assert!(drawing, "{backend}: the viewer did not start drawing");
        // The first frame reaches the screen after "drawing on" by a time that depends on the
        // machine's load: look every half second for up to 30 s.
        let started = std::time::Instant::now();
        let n = loop {
            std::thread::sleep(Duration::from_millis(500));
            let grab = Command::new("xwd").args(["-root", "-silent", "-display", &x.display]).output().unwrap();
            assert!(grab.status.success(), "{backend}: xwd failed");
            let (w, h, rgba) = read_xwd(&grab.stdout);
            assert_eq!((w, h), (800, 600));
            let n = colours(&rgba);
            if n > 50 || started.elapsed() > Duration::from_secs(30) {
                break n;
            }
        };
        let _ = child.kill();
        let _ = child.wait();
        assert!(n > 50, "{backend}: the screen shows only {n} colours after {:?}", started.elapsed());
    }
}

/// Without a display the viewer says so and how to get one, in its own words: not the
/// windowing library's, which name a source file of its crate; exit 2, as for no adapter.
#[cfg(all(unix, not(target_os = "macos")))]
#[test]
fn without_a_display_the_viewer_says_how_to_get_one() {
    let out = Command::new(env!("CARGO_BIN_EXE_wgsph"))
        .args(["view", "hydrostatic"])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .env_remove("WAYLAND_SOCKET")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("cannot open a window: no display") && err.contains("Xvfb"), "{err}");
    assert!(!err.contains(".rs:"), "{err}");
}

/// The screenshot's path is checked before any window opens: an existing file (a PNG carries
/// no mark of who wrote it) or a directory is refused with exit 2 and left alone, and a missing
/// directory is not created.
#[test]
fn a_screenshot_never_replaces_an_existing_file() {
    let dir = tempfile::tempdir().unwrap();
    let photo = dir.path().join("photo.png");
    std::fs::write(&photo, "my picture").unwrap();
    let missing = dir.path().join("no_such_dir/shot.png");
    for (path, says) in [(photo.as_path(), "exists, and wgsph replaces only its own output"), (dir.path(), "is a directory"), (missing.as_path(), "is not a directory")] {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_wgsph")).args(["view", "hydrostatic", "--quit-after", "1", "--screenshot"]).arg(path).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{}: {err}", path.display());
        assert!(err.contains(&format!("--screenshot {}: ", path.display())) && err.contains(says), "{err}");
    }
    assert_eq!(std::fs::read_to_string(&photo).unwrap(), "my picture");
    assert!(!dir.path().join("no_such_dir").exists());
}
