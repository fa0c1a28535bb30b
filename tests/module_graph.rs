//! The library's top-level modules depend on each other one way only (ARCHITECTURE.md,
//! "Layout"): this test reads `src/`, takes every `crate::<module>` path in each top-level
//! module's code (comments and `#[cfg(test)] mod tests` blocks aside: tests may reach anywhere)
//! and fails on any cycle in that graph, naming the modules and one place of each edge.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Every `.rs` file of a top-level module: `src/NAME.rs` and everything under `src/NAME/`.
fn files_of(src: &Path, module: &str) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let file = src.join(format!("{module}.rs"));
    if file.is_file() {
        out.push(file);
    }
    let mut dirs = vec![src.join(module)];
    while let Some(dir) = dirs.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries {
            let path = entry.unwrap().path();
            if path.is_dir() {
                dirs.push(path);
            } else if path.extension().is_some_and(|x| x == "rs") {
                out.push(path);
            }
        }
    }
    out
}

/// The code of a file that production builds compile: up to its `#[cfg(test)] mod tests`
/// block, without comments. `tests.rs` files and files marked `#![cfg(test)]` hold only tests.
fn production_lines(path: &Path) -> Vec<(usize, String)> {
    if path.file_name().is_some_and(|n| n == "tests.rs") {
        return Vec::new();
    }
    let text = std::fs::read_to_string(path).unwrap();
    if text.lines().any(|l| l.trim() == "#![cfg(test)]") {
        return Vec::new();
    }
    let mut out = Vec::new();
    let mut lines = text.lines().enumerate().peekable();
    while let Some((i, line)) = lines.next() {
        let code = line.trim();
        if code == "#[cfg(test)]"
            && lines
                .peek()
                .is_some_and(|(_, next)| next.trim().starts_with("mod tests"))
        {
            break;
        }
        if code.starts_with("//") {
            continue;
        }
        out.push((i + 1, code.to_string()));
    }
    out
}

/// The top-level modules `line` names as `crate::<module>`.
fn named_modules<'m>(line: &str, modules: &'m BTreeSet<String>) -> Vec<&'m str> {
    line.match_indices("crate::")
        .filter_map(|(at, prefix)| {
            let name: String = line[at + prefix.len()..]
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            modules.get(&name).map(String::as_str)
        })
        .collect()
}

#[test]
fn the_top_level_modules_form_no_cycle() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let modules: BTreeSet<String> = std::fs::read_dir(&src)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter_map(|p| {
            let stem = p.file_stem()?.to_str()?.to_string();
            (p.is_dir() || p.extension().is_some_and(|x| x == "rs")).then_some(stem)
        })
        .filter(|m| m != "lib" && m != "main")
        .collect();
    assert!(modules.len() > 20, "the modules of src/: {modules:?}");

    // module -> (module it names -> one place it does so)
    let mut edges: BTreeMap<&str, BTreeMap<&str, String>> = BTreeMap::new();
    for module in &modules {
        let out = edges.entry(module.as_str()).or_default();
        for file in files_of(&src, module) {
            for (n, line) in production_lines(&file) {
                for named in named_modules(&line, &modules) {
                    if named != module {
                        out.entry(named).or_insert_with(|| {
                            let shown = file.strip_prefix(src.parent().unwrap()).unwrap();
                            format!("{}:{n}", shown.display())
                        });
                    }
                }
            }
        }
    }

    // Depth-first search; a grey node met again closes a cycle.
    #[derive(Clone, Copy, PartialEq)]
    enum Mark {
        White,
        Grey,
        Black,
    }
    fn visit<'a>(
        m: &'a str,
        edges: &BTreeMap<&'a str, BTreeMap<&'a str, String>>,
        marks: &mut BTreeMap<&'a str, Mark>,
        path: &mut Vec<&'a str>,
    ) -> Option<Vec<&'a str>> {
        marks.insert(m, Mark::Grey);
        path.push(m);
        for &next in edges[m].keys() {
            match marks[next] {
                Mark::Grey => {
                    let from = path.iter().position(|&p| p == next).unwrap();
                    let mut cycle = path[from..].to_vec();
                    cycle.push(next);
                    return Some(cycle);
                }
                Mark::White => {
                    if let Some(cycle) = visit(next, edges, marks, path) {
                        return Some(cycle);
                    }
                }
                Mark::Black => {}
            }
        }
        path.pop();
        marks.insert(m, Mark::Black);
        None
    }
    let mut marks: BTreeMap<&str, Mark> = edges.keys().map(|&m| (m, Mark::White)).collect();
    for &m in edges.keys() {
        if marks[m] == Mark::White
            && let Some(cycle) = visit(m, &edges, &mut marks, &mut Vec::new())
        {
            let steps: Vec<String> = cycle
                .windows(2)
                .map(|w| format!("{} -> {} ({})", w[0], w[1], edges[w[0]][w[1]]))
                .collect();
            panic!("a cycle between top-level modules:\n{}", steps.join("\n"));
        }
    }
    // The graph is not empty: the check above saw real edges.
    assert!(
        edges["service"].contains_key("store"),
        "{:?}",
        edges["service"]
    );
}
