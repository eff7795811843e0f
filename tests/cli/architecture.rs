//! The source's floors, read from the files themselves: every `crate::`, `super::` and
//! `self::` path and every path through a child module is resolved to the file that defines
//! it, and the test fails on a file that imports from a floor above its own, on any import of
//! `app` from outside it, and on any loop between files (the floors are model < solver < io <
//! viz < app; docs/design.md).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

const FLOORS: [&str; 5] = ["model", "solver", "io", "viz", "app"];

/// Every .rs file under `dir`.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The module path of a file: src/solver/gpu/solver.rs -> solver::gpu::solver,
/// src/solver/mod.rs -> solver, src/lib.rs -> (the crate root).
fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).unwrap();
    let mut parts: Vec<String> = rel.iter().map(|c| c.to_string_lossy().into_owned()).collect();
    let last = parts.pop().unwrap();
    match last.as_str() {
        "mod.rs" | "lib.rs" | "main.rs" => {}
        other => parts.push(other.trim_end_matches(".rs").to_string()),
    }
    parts
}

/// The file that defines module `path`, if it is one.
fn file_of(src: &Path, path: &[String]) -> Option<PathBuf> {
    if path.is_empty() {
        return Some(src.join("lib.rs"));
    }
    let base = path.iter().fold(src.to_path_buf(), |p, s| p.join(s));
    let file = base.with_extension("rs");
    if file.is_file() {
        return Some(file);
    }
    let dir = base.join("mod.rs");
    dir.is_file().then_some(dir)
}

/// The text without comments and string literals (so a path in a doc comment or a message is
/// not an import).
fn code_of(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let b = text.as_bytes();
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'/' && i + 1 < b.len() && b[i + 1] == b'/' {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if b[i] == b'/' && i + 1 < b.len() && b[i + 1] == b'*' {
            i += 2;
            while i + 1 < b.len() && !(b[i] == b'*' && b[i + 1] == b'/') {
                i += 1;
            }
            i += 2;
        } else if b[i] == b'"' {
            i += 1;
            while i < b.len() && b[i] != b'"' {
                if b[i] == b'\\' {
                    i += 1;
                }
                i += 1;
            }
            i += 1;
            out.push_str("\"\"");
        } else if b[i] == b'\'' && i + 2 < b.len() && (b[i + 2] == b'\'' || (b[i + 1] == b'\\' && i + 3 < b.len() && b[i + 3] == b'\'')) {
            // A char literal ('"', '\n'); lifetimes have no closing quote.
            i += if b[i + 1] == b'\\' { 4 } else { 3 };
        } else {
            out.push(b[i] as char);
            i += 1;
        }
    }
    out
}

/// The paths of `use` trees, expanded: `use a::{b, c::{d, e}}` gives a::b, a::c::d, a::c::e.
fn expand_use(tree: &str, prefix: &str, out: &mut Vec<String>) {
    let tree = tree.trim();
    if let Some(open) = tree.find('{') {
        let head = tree[..open].trim_end_matches("::");
        let inner = &tree[open + 1..tree.rfind('}').unwrap()];
        let mut depth = 0;
        let mut start = 0;
        let joined = join(prefix, head);
        for (i, c) in inner.char_indices() {
            match c {
                '{' => depth += 1,
                '}' => depth -= 1,
                ',' if depth == 0 => {
                    expand_use(&inner[start..i], &joined, out);
                    start = i + 1;
                }
                _ => {}
            }
        }
        expand_use(&inner[start..], &joined, out);
    } else if !tree.is_empty() {
        let item = tree.split(" as ").next().unwrap().trim();
        out.push(join(prefix, item));
    }
}

fn join(a: &str, b: &str) -> String {
    match (a.is_empty(), b.is_empty()) {
        (true, _) => b.to_string(),
        (_, true) => a.to_string(),
        _ => format!("{a}::{b}"),
    }
}

/// Every path the code names that starts with a module: `crate::`, `super::`, `self::`, or a
/// child module of this file.
fn paths_in(code: &str, children: &BTreeSet<String>) -> Vec<String> {
    let mut out = Vec::new();
    // `use` statements, with their trees expanded.
    let mut rest = code;
    while let Some(at) = rest.find("use ") {
        let before = rest[..at].chars().last();
        let after = &rest[at + 4..];
        let end = after.find(';').unwrap_or(after.len());
        if before.is_none_or(|c| !(c.is_alphanumeric() || c == '_')) {
            expand_use(&after[..end], "", &mut out);
        }
        rest = &after[end.min(after.len())..];
    }
    // Paths anywhere else.
    let bytes = code.as_bytes();
    let mut i = 0;
    while i < bytes.len() {
        let starts_word = i == 0 || !(bytes[i - 1].is_ascii_alphanumeric() || bytes[i - 1] == b'_' || bytes[i - 1] == b':');
        if starts_word && (bytes[i].is_ascii_alphabetic() || bytes[i] == b'_') {
            let mut j = i;
            while j < bytes.len() && (bytes[j].is_ascii_alphanumeric() || bytes[j] == b'_' || bytes[j] == b':') {
                j += 1;
            }
            let word = &code[i..j];
            let first = word.split("::").next().unwrap();
            if word.contains("::") && (["crate", "super", "self"].contains(&first) || children.contains(first)) {
                out.push(word.trim_end_matches(':').to_string());
            }
            i = j;
        } else {
            i += 1;
        }
    }
    out
}

/// The file a path leads to: the deepest module along it that has a file.
fn resolve(src: &Path, here: &[String], path: &str) -> Option<PathBuf> {
    let mut segments: Vec<&str> = path.split("::").filter(|s| !s.is_empty()).collect();
    let mut module: Vec<String> = match segments.first().copied() {
        Some("crate") => {
            segments.remove(0);
            Vec::new()
        }
        Some("self") => {
            segments.remove(0);
            here.to_vec()
        }
        Some("super") => {
            let mut m = here.to_vec();
            while segments.first() == Some(&"super") {
                segments.remove(0);
                m.pop();
            }
            m
        }
        _ => here.to_vec(),
    };
    let mut found = None;
    for s in segments {
        module.push(s.to_string());
        match file_of(src, &module) {
            Some(f) => found = Some(f),
            None => break,
        }
    }
    found
}

fn floor_of(src: &Path, file: &Path) -> Option<usize> {
    let first = file.strip_prefix(src).unwrap().iter().next()?.to_string_lossy().into_owned();
    FLOORS.iter().position(|f| *f == first || format!("{f}.rs") == first)
}

#[test]
fn floors_hold_and_no_file_imports_in_a_loop() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    let mut edges: BTreeMap<PathBuf, BTreeSet<PathBuf>> = BTreeMap::new();
    let mut problems = Vec::new();
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap();
        let code = code_of(&text);
        let here = module_of(&src, file);
        // Child modules declared here (`mod x;`): a path through them is an import too.
        let children: BTreeSet<String> = code
            .lines()
            .filter_map(|l| l.trim().trim_start_matches("pub ").strip_prefix("mod ")?.strip_suffix(';').map(str::to_string))
            .collect();
        // Paths are relative to this file's module (a mod.rs is its own directory's module).
        let mut targets = BTreeSet::new();
        for path in paths_in(&code, &children) {
            if let Some(t) = resolve(&src, &here, &path) {
                if &t != file {
                    targets.insert(t);
                }
            }
        }
        let name = |f: &Path| f.strip_prefix(&src).unwrap().display().to_string();
        for t in &targets {
            if file.file_name().is_some_and(|n| n == "lib.rs" || n == "main.rs") {
                continue;
            }
            match (floor_of(&src, file), floor_of(&src, t)) {
                (Some(a), Some(b)) if b > a => problems.push(format!("{} (floor {}) imports {} (floor {})", name(file), FLOORS[a], name(t), FLOORS[b])),
                (_, None) => problems.push(format!("{} imports {}, which is in no floor", name(file), name(t))),
                _ => {}
            }
        }
        edges.insert(file.clone(), targets);
    }
    // Loops: strongly connected components of more than one file (Tarjan).
    let index: BTreeMap<&PathBuf, usize> = files.iter().enumerate().map(|(i, f)| (f, i)).collect();
    let adjacency: Vec<Vec<usize>> = files.iter().map(|f| edges[f].iter().filter_map(|t| index.get(t).copied()).collect()).collect();
    for component in strongly_connected(&adjacency) {
        if component.len() > 1 {
            let names: Vec<String> = component.iter().map(|&i| files[i].strip_prefix(&src).unwrap().display().to_string()).collect();
            problems.push(format!("these files import each other in a loop: {}", names.join(", ")));
        }
    }
    assert!(edges.values().map(BTreeSet::len).sum::<usize>() > 100, "the reader found too few imports to be reading the code");
    assert!(problems.is_empty(), "{} problems:\n{}", problems.len(), problems.join("\n"));
}

/// Tarjan's strongly connected components.
fn strongly_connected(adjacency: &[Vec<usize>]) -> Vec<Vec<usize>> {
    struct State<'a> {
        adjacency: &'a [Vec<usize>],
        index: Vec<Option<usize>>,
        low: Vec<usize>,
        on_stack: Vec<bool>,
        stack: Vec<usize>,
        next: usize,
        out: Vec<Vec<usize>>,
    }
    fn visit(s: &mut State, v: usize) {
        s.index[v] = Some(s.next);
        s.low[v] = s.next;
        s.next += 1;
        s.stack.push(v);
        s.on_stack[v] = true;
        for k in 0..s.adjacency[v].len() {
            let w = s.adjacency[v][k];
            match s.index[w] {
                None => {
                    visit(s, w);
                    s.low[v] = s.low[v].min(s.low[w]);
                }
                Some(iw) if s.on_stack[w] => s.low[v] = s.low[v].min(iw),
                _ => {}
            }
        }
        if Some(s.low[v]) == s.index[v] {
            let mut component = Vec::new();
            loop {
                let w = s.stack.pop().unwrap();
                s.on_stack[w] = false;
                component.push(w);
                if w == v {
                    break;
                }
            }
            s.out.push(component);
        }
    }
    let n = adjacency.len();
    let mut s = State { adjacency, index: vec![None; n], low: vec![0; n], on_stack: vec![false; n], stack: Vec::new(), next: 0, out: Vec::new() };
    for v in 0..n {
        if s.index[v].is_none() {
            visit(&mut s, v);
        }
    }
    s.out
}

#[test]
fn the_checker_sees_a_loop_and_a_floor_broken() {
    let adjacency = vec![vec![1], vec![2], vec![0], vec![]];
    let loops: Vec<Vec<usize>> = strongly_connected(&adjacency).into_iter().filter(|c| c.len() > 1).collect();
    assert_eq!(loops.len(), 1);
    assert_eq!(loops[0].len(), 3);
    let mut paths = Vec::new();
    expand_use("crate::model::{scene::{Scene, SceneError}, params::Params as P}", "", &mut paths);
    assert_eq!(paths, ["crate::model::scene::Scene", "crate::model::scene::SceneError", "crate::model::params::Params"]);
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let here = module_of(&src, &src.join("solver/gpu/solver.rs"));
    assert_eq!(resolve(&src, &here, "super::device::GpuContext"), Some(src.join("solver/gpu/device.rs")));
    assert_eq!(resolve(&src, &here, "crate::model::kernels::sort_by_cell"), Some(src.join("model/kernels.rs")));
    assert_eq!(floor_of(&src, &src.join("app/run.rs")), Some(4));
    assert!(code_of("let a = \"crate::app::x\"; // crate::app::y").find("crate::app").is_none());
}
