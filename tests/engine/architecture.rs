//! The floor plan of docs/architecture.md against the library's actual `use` graph: every
//! top-level module is on a floor, every reference to another top-level module goes to a
//! lower floor, and no two modules (at any depth) reach each other in a cycle.
//!
//! The graph is read from the source text: a reference is a path `crate::a::b…` or
//! `super::…` outside comments and strings (doc links are not imports; `super` counts the
//! inline modules a path sits in), resolved to the longest module it names and then through
//! that module's `pub use` re-exports (named or glob) to the module defining the item. A
//! module's references to its own ancestors and descendants are not edges: a `mod.rs`
//! declares and re-exports its children and holds the vocabulary they share. Not read:
//! raw strings with unbalanced quotes, nested block comments, paths built by macros (none
//! in `src/` today).

use crate::support::repo_root;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Module path (`raster::composite`) → its source text without comments.
fn modules(src: &Path) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    let mut stack = vec![src.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
                continue;
            }
            if p.extension().is_none_or(|x| x != "rs") {
                continue;
            }
            let rel = p.strip_prefix(src).unwrap().with_extension("");
            let mut parts: Vec<String> = rel
                .iter()
                .map(|c| c.to_string_lossy().into_owned())
                .collect();
            if parts.last().is_some_and(|l| l == "mod") {
                parts.pop();
            }
            if parts == ["lib"] {
                continue;
            }
            let text = std::fs::read_to_string(&p).unwrap();
            out.insert(parts.join("::"), strip_comments(&text));
        }
    }
    out
}

/// The text with `//…` line comments and `/*…*/` block comments removed and the contents
/// of string literals blanked (a path in a message is not an import; a `//` in a string is
/// not a comment).
fn strip_comments(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = String::with_capacity(s.len());
    let (mut i, mut in_str) = (0, false);
    while i < b.len() {
        if in_str {
            if b[i] == b'\\' {
                out.push_str("  ");
                i += 2;
                continue;
            }
            if b[i] == b'"' {
                in_str = false;
                out.push('"');
            } else {
                out.push(' ');
            }
            i += 1;
        } else if b[i..].starts_with(b"//") {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if b[i..].starts_with(b"/*") {
            let end = s[i + 2..].find("*/").map_or(b.len(), |k| i + 2 + k + 2);
            i = end;
        } else {
            if b[i] == b'"' && !(i > 0 && matches!(b[i - 1], b'\'' | b'\\')) {
                in_str = true;
            }
            // Non-ASCII bytes only occur in strings and comments; keep them as spaces.
            out.push(if b[i].is_ascii() { b[i] as char } else { ' ' });
            i += 1;
        }
    }
    out
}

/// Every path a text names from `crate::` or `super::` (brace groups expanded), as the
/// list of its segments after `crate`. `super` is resolved against `module` plus the
/// inline modules (`mod tests { … }`) the path sits in.
fn referenced_paths(module: &[&str], text: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let bytes = text.as_bytes();
    let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    // Inline modules open at this position: (name, brace depth inside it).
    let mut inline: Vec<(String, usize)> = Vec::new();
    let (mut depth, mut pending): (usize, Option<String>) = (0, None);
    for start in 0..bytes.len() {
        match bytes[start] {
            b'{' => {
                depth += 1;
                if let Some(name) = pending.take() {
                    inline.push((name, depth));
                }
            }
            b'}' => {
                if inline.last().is_some_and(|&(_, d)| d == depth) {
                    inline.pop();
                }
                depth = depth.saturating_sub(1);
            }
            b';' => pending = None,
            _ => {}
        }
        if start > 0 && (ident(bytes[start - 1]) || bytes[start - 1] == b':') {
            continue;
        }
        let rest = &text[start..];
        if let Some(r) = rest.strip_prefix("mod ") {
            let r = r.trim_start();
            let n = r
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .unwrap_or(r.len());
            if n > 0 && r[n..].trim_start().starts_with('{') {
                pending = Some(r[..n].to_string());
            }
            continue;
        }
        let (mut base, mut tail): (Vec<String>, &str) =
            if let Some(t) = rest.strip_prefix("crate::") {
                (Vec::new(), t)
            } else if rest.starts_with("super::") {
                // `super` of `a::b` is `a`, whether `b` is a file, a folder's `mod.rs` or an
                // inline module.
                let mut base: Vec<String> = module.iter().map(|s| s.to_string()).collect();
                base.extend(inline.iter().map(|(n, _)| n.clone()));
                let mut t = rest;
                while let Some(r) = t.strip_prefix("super::") {
                    base.pop();
                    t = r;
                }
                (base, t)
            } else {
                continue;
            };
        expand(&mut base, &mut tail, &mut out);
    }
    out
}

/// What each module re-exports: (module, name) → the path it stands for, from
/// `pub use` / `pub(crate) use` items (a name relative to the module is its child's);
/// and (module, `*`) → the modules it re-exports whole.
fn reexports(mods: &BTreeMap<String, String>) -> BTreeMap<(String, String), Vec<String>> {
    let mut out = BTreeMap::new();
    for (m, text) in mods {
        let parts: Vec<&str> = m.split("::").collect();
        for stmt in text.split(';') {
            let s = stmt.trim();
            let Some(rest) = s
                .strip_prefix("pub use ")
                .or_else(|| s.strip_prefix("pub(crate) use "))
                .or_else(|| s.strip_prefix("pub(super) use "))
            else {
                continue;
            };
            // A path relative to the module: its child (what `pub use child::x` means).
            let rel = if rest.starts_with("crate::") || rest.starts_with("super::") {
                rest.to_string()
            } else {
                format!("crate::{m}::{rest}")
            };
            for path in referenced_paths(&parts, &rel) {
                let Some(name) = path.last().cloned() else {
                    continue;
                };
                let key = if name.is_empty() {
                    "*".to_string()
                } else {
                    name
                };
                let entry: &mut Vec<String> = out.entry((m.clone(), key.clone())).or_default();
                let target = if key == "*" {
                    path[..path.len() - 1].join("::")
                } else {
                    path.join("::")
                };
                entry.push(target);
            }
        }
    }
    out
}

/// Read the path segments at the start of `tail` onto `base`, expanding a `{…}` group
/// into one path per member, and push the results.
fn expand(base: &mut [String], tail: &mut &str, out: &mut Vec<Vec<String>>) {
    let mut path = base.to_vec();
    loop {
        let t = tail.trim_start();
        if let Some(group) = t.strip_prefix('{') {
            // Split the group at its top-level commas.
            let (mut depth, mut end) = (1, group.len());
            for (k, c) in group.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' => {
                        depth -= 1;
                        if depth == 0 {
                            end = k;
                            break;
                        }
                    }
                    _ => {}
                }
            }
            let inner = &group[..end];
            let (mut depth, mut from) = (0, 0);
            let mut members = Vec::new();
            for (k, c) in inner.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' => depth -= 1,
                    ',' if depth == 0 => {
                        members.push(&inner[from..k]);
                        from = k + 1;
                    }
                    _ => {}
                }
            }
            members.push(&inner[from..]);
            for m in members {
                let mut m = m.trim();
                if m.is_empty() {
                    continue;
                }
                expand(&mut path, &mut m, out);
            }
            return;
        }
        let n = t
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap_or(t.len());
        if n == 0 {
            if t.starts_with('*') {
                path.push(String::new());
            }
            break;
        }
        path.push(t[..n].to_string());
        *tail = &t[n..];
        match tail.strip_prefix("::") {
            Some(r) => *tail = r,
            None => break,
        }
    }
    out.push(path);
}

/// The floor of each top-level module, from the table in docs/architecture.md: rows
/// `| N | `a`, `b` | … |`.
fn floors(doc: &str) -> BTreeMap<String, u32> {
    let mut out = BTreeMap::new();
    for line in doc.lines() {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        if cells.len() < 4 {
            continue;
        }
        let Ok(floor) = cells[1].parse::<u32>() else {
            continue;
        };
        for room in cells[2].split(',') {
            let room = room.trim().trim_matches('`');
            assert!(
                out.insert(room.to_string(), floor).is_none(),
                "docs/architecture.md lists `{room}` twice"
            );
        }
    }
    out
}

/// The module a path names: its longest prefix that is a module, followed through that
/// module's re-exports (named or glob) to the module that defines the item.
fn resolve(
    mods: &BTreeMap<String, String>,
    re: &BTreeMap<(String, String), Vec<String>>,
    path: &[String],
    hops: usize,
) -> Option<String> {
    let k = (1..=path.len())
        .rev()
        .find(|&k| mods.contains_key(&path[..k].join("::")))?;
    let module = path[..k].join("::");
    let Some(item) = path.get(k).filter(|s| !s.is_empty()) else {
        return Some(module);
    };
    if hops < 8 {
        if let Some(targets) = re.get(&(module.clone(), item.clone())) {
            let target: Vec<String> = targets[0].split("::").map(String::from).collect();
            return resolve(mods, re, &target, hops + 1);
        }
        // A glob re-export of a module that defines or re-exports the item.
        for g in re
            .get(&(module.clone(), "*".to_string()))
            .into_iter()
            .flatten()
        {
            let defines = mods.get(g).is_some_and(|text| {
                [
                    "fn", "struct", "enum", "const", "static", "type", "trait", "mod",
                ]
                .iter()
                .any(|kw| text.contains(&format!("{kw} {item}")))
            });
            if defines || re.contains_key(&(g.clone(), item.clone())) {
                let mut target: Vec<String> = g.split("::").map(String::from).collect();
                target.push(item.clone());
                return resolve(mods, re, &target, hops + 1);
            }
        }
    }
    Some(module)
}

/// The module graph: module → modules it references (excluding its ancestors and
/// descendants), each reference followed through re-exports to where the item lives.
fn graph(mods: &BTreeMap<String, String>) -> BTreeMap<String, BTreeSet<String>> {
    let re = reexports(mods);
    let mut edges: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (m, text) in mods {
        let parts: Vec<&str> = m.split("::").collect();
        let set = edges.entry(m.clone()).or_default();
        for path in referenced_paths(&parts, text) {
            let Some(t) = resolve(mods, &re, &path, 0) else {
                continue;
            };
            let related =
                t == *m || m.starts_with(&format!("{t}::")) || t.starts_with(&format!("{m}::"));
            if !related {
                set.insert(t);
            }
        }
    }
    edges
}

/// The strongly connected components with more than one module (Tarjan).
fn cycles(edges: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    struct T<'a> {
        e: &'a BTreeMap<String, BTreeSet<String>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on: BTreeSet<&'a str>,
        out: Vec<Vec<String>>,
    }
    fn visit<'a>(t: &mut T<'a>, v: &'a str) {
        let i = t.index.len();
        t.index.insert(v, i);
        t.low.insert(v, i);
        t.stack.push(v);
        t.on.insert(v);
        for w in t.e.get(v).into_iter().flatten() {
            let w = w.as_str();
            if !t.index.contains_key(w) {
                visit(t, w);
                let lw = t.low[w];
                let lv = t.low.get_mut(v).unwrap();
                *lv = (*lv).min(lw);
            } else if t.on.contains(w) {
                let iw = t.index[w];
                let lv = t.low.get_mut(v).unwrap();
                *lv = (*lv).min(iw);
            }
        }
        if t.low[v] == t.index[v] {
            let mut comp = Vec::new();
            loop {
                let w = t.stack.pop().unwrap();
                t.on.remove(w);
                comp.push(w.to_string());
                if w == v {
                    break;
                }
            }
            if comp.len() > 1 {
                comp.sort();
                t.out.push(comp);
            }
        }
    }
    let mut t = T {
        e: edges,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on: BTreeSet::new(),
        out: Vec::new(),
    };
    for v in edges.keys() {
        if !t.index.contains_key(v.as_str()) {
            visit(&mut t, v);
        }
    }
    t.out
}

/// The floor plan holds: each top-level module on one floor of docs/architecture.md,
/// references only downward, and no cycle between modules at any depth.
#[test]
fn modules_import_only_downward_and_without_cycles() {
    let root = repo_root();
    let doc = std::fs::read_to_string(root.join("docs/architecture.md")).unwrap();
    let floor = floors(&doc);
    let mods = modules(&root.join("src"));
    let edges = graph(&mods);

    let top = |m: &str| m.split("::").next().unwrap().to_string();
    let tops: BTreeSet<String> = mods.keys().map(|m| top(m)).collect();
    let listed: BTreeSet<String> = floor.keys().cloned().collect();
    assert_eq!(
        tops, listed,
        "docs/architecture.md's floors must list exactly the library's top-level modules"
    );
    let mut upward = Vec::new();
    for (a, bs) in &edges {
        for b in bs {
            let (ta, tb) = (top(a), top(b));
            if ta != tb && floor[&ta] <= floor[&tb] {
                upward.push(format!(
                    "{a} (floor {}) -> {b} (floor {})",
                    floor[&ta], floor[&tb]
                ));
            }
        }
    }
    assert!(
        upward.is_empty(),
        "imports that do not go to a lower floor:\n{}",
        upward.join("\n")
    );
    let cyc = cycles(&edges);
    assert!(cyc.is_empty(), "module cycles: {cyc:?}");
}

/// The checker sees what it must: a `super` chain, a brace group, a path inside a
/// function body, and not a path in a comment or a string.
#[test]
fn architecture_checker_reads_references() {
    let text = strip_comments(
        "use super::super::a::{b::C, d};\n// crate::hidden\nfn f() { crate::e::g(); let s = \"crate::nope\"; }\n",
    );
    let got = referenced_paths(&["x", "y", "z"], &text);
    let got: Vec<String> = got.iter().map(|p| p.join("::")).collect();
    assert_eq!(got, ["x::a::b::C", "x::a::d", "e::g"]);
    // `super` inside an inline module is the file's module.
    let got = referenced_paths(&["x", "y"], "mod tests { use super::Z; }\nuse super::W;");
    let got: Vec<String> = got.iter().map(|p| p.join("::")).collect();
    assert_eq!(got, ["x::y::Z", "x::W"]);
    // A re-export is followed to the module that defines the item.
    let mods: BTreeMap<String, String> = [
        ("p", "pub use q::Thing; pub use r::*;"),
        ("p::q", "pub struct Thing;"),
        ("p::r", "pub fn helper() {}"),
        ("s", "use crate::p::Thing; fn f() { crate::p::helper(); }"),
    ]
    .into_iter()
    .map(|(m, t)| (m.to_string(), t.to_string()))
    .collect();
    let g = graph(&mods);
    assert_eq!(
        g["s"],
        BTreeSet::from(["p::q".to_string(), "p::r".to_string()])
    );
    let mut e = BTreeMap::new();
    e.insert("a".to_string(), BTreeSet::from(["b".to_string()]));
    e.insert("b".to_string(), BTreeSet::from(["a".to_string()]));
    assert_eq!(cycles(&e), vec![vec!["a".to_string(), "b".to_string()]]);
}

/// The string literals of a Rust source text outside comments, each with the 6 characters of code
/// before it (to tell `join("views")` from a JSON key).
fn string_literals(s: &str) -> Vec<(String, String)> {
    let b = s.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i..].starts_with(b"//") {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if b[i..].starts_with(b"/*") {
            i = s[i + 2..].find("*/").map_or(b.len(), |k| i + 2 + k + 2);
        } else if b[i] == b'"' && !(i > 0 && matches!(b[i - 1], b'\'' | b'\\')) {
            let before = s[..i]
                .char_indices()
                .rev()
                .nth(5)
                .map_or("", |(k, _)| &s[k..i]);
            let mut j = i + 1;
            while j < b.len() && b[j] != b'"' {
                j += if b[j] == b'\\' { 2 } else { 1 };
            }
            out.push((s[i + 1..j.min(b.len())].to_string(), before.to_string()));
            i = j + 1;
        } else {
            i += 1;
        }
    }
    out
}

/// Issue #53: a step's folder name is written only in `pipeline::steps` (`Step`'s
/// `Display` / `FromStr`). Anywhere else in the engine or the CLI, a string literal holding
/// a step path (`stage1/…`, `…/eval/…`, `--until views`) or a `join("<stage folder>")` is a
/// second copy of the run's structure that a renamed step would silently break.
#[test]
fn step_names_live_in_steps_rs() {
    let root = repo_root();
    let folders = [
        "views",
        "stage1",
        "stage2",
        "interpolate",
        "cycle",
        "eval",
        "qa",
    ];
    let mut found = Vec::new();
    let mut stack = vec![root.join("src"), root.join("cli/src")];
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
                continue;
            }
            if p.extension().is_none_or(|x| x != "rs") || p.ends_with("pipeline/steps.rs") {
                continue;
            }
            let text = std::fs::read_to_string(&p).unwrap();
            for (lit, before) in string_literals(&text) {
                let path_like = folders.iter().any(|f| {
                    lit.match_indices(&format!("{f}/")).any(|(k, _)| {
                        k == 0 || matches!(lit.as_bytes()[k - 1], b'/' | b'}' | b' ' | b'(')
                    }) || lit.ends_with(&format!("/{f}"))
                        || lit.contains(&format!("--until {f}"))
                        || lit.contains(&format!("--only {f}"))
                });
                let joined = folders.contains(&lit.as_str()) && before.ends_with("join(");
                if path_like || joined {
                    found.push(format!(
                        "{}: \"{lit}\"",
                        p.strip_prefix(&root).unwrap().display()
                    ));
                }
            }
        }
    }
    assert!(
        found.is_empty(),
        "step names outside pipeline/steps.rs: {found:#?}"
    );
    // The scanner sees what it must.
    let probe =
        "let a = dir.join(\"eval\"); // \"stage1/x\"\nlet b = format!(\"{p}/stage2/videos\");";
    let lits = string_literals(probe);
    assert_eq!(lits.len(), 2, "{lits:?}");
    assert_eq!(lits[0], ("eval".to_string(), ".join(".to_string()));
}
