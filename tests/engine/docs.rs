//! The front page read as a newcomer reads it (issue #74): short, in paragraphs one takes in
//! at a glance, its numbers about the tests true, its pictures present.
use crate::support::repo_root;
use std::path::Path;

/// README.md's limits: lines on the page and words in one paragraph.
const README_MAX_LINES: usize = 150;
const PARAGRAPH_MAX_WORDS: usize = 120;

/// The prose paragraphs of a markdown page: runs of text lines between blank lines, each
/// list item its own; code fences, tables, headings and HTML comments are not prose.
fn paragraphs(text: &str) -> Vec<String> {
    let (mut out, mut cur, mut fence) = (Vec::new(), Vec::<&str>::new(), false);
    let mut flush = |cur: &mut Vec<&str>| {
        if !cur.is_empty() {
            out.push(cur.join(" "));
            cur.clear();
        }
    };
    for line in text.lines() {
        if line.starts_with("```") {
            fence = !fence;
            flush(&mut cur);
            continue;
        }
        let t = line.trim_start();
        if fence
            || t.is_empty()
            || t.starts_with('|')
            || t.starts_with('#')
            || t.starts_with("<!--")
        {
            flush(&mut cur);
            continue;
        }
        if t.starts_with("- ") {
            flush(&mut cur);
        }
        cur.push(line);
    }
    flush(&mut cur);
    out
}

/// The tests marked `slow tier` in the crate's sources (`#[ignore = "slow tier …"]`).
fn slow_tier_tests(dir: &Path) -> usize {
    let mut n = 0;
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            n += slow_tier_tests(&p);
        } else if p.extension().is_some_and(|x| x == "rs") {
            let text = std::fs::read_to_string(&p).unwrap();
            n += text
                .lines()
                .filter(|l| l.trim_start().starts_with("#[ignore = \"slow tier"))
                .count();
        }
    }
    n
}

/// README.md fits in `README_MAX_LINES`, no paragraph runs past `PARAGRAPH_MAX_WORDS`
/// words, the number of slow-tier tests it states is the number there are, and every
/// picture it and the audit page show is in the repository.
#[test]
fn the_readme_is_short_true_and_complete() {
    let root = repo_root();
    let text = std::fs::read_to_string(root.join("README.md")).unwrap();
    let lines = text.lines().count();
    assert!(lines <= README_MAX_LINES, "README.md has {lines} lines");
    for p in paragraphs(&text) {
        let words = p.split_whitespace().count();
        assert!(
            words <= PARAGRAPH_MAX_WORDS,
            "a README paragraph of {words} words: {}…",
            &p[..p.len().min(80)]
        );
    }
    let slow = slow_tier_tests(&root.join("tests")) + slow_tier_tests(&root.join("src"));
    let stated = format!("{slow} tests marked `slow tier`");
    assert!(text.contains(&stated), "README.md should say \"{stated}\"");
    assert!(
        !pictures(&root, "README.md").is_empty(),
        "README.md shows no picture"
    );
    assert!(
        pictures(&root, "reference_data/audit/README.md").len() >= 3,
        "the audit page shows its plots"
    );
}

/// The pictures `page` shows (`![…](target)`, relative to the page), each checked present.
fn pictures(root: &Path, page: &str) -> Vec<String> {
    let path = root.join(page);
    let text = std::fs::read_to_string(&path).unwrap();
    let mut rest = text.as_str();
    let mut out = Vec::new();
    while let Some((_, after)) = rest.split_once("![") {
        let (_, after) = after.split_once("](").unwrap();
        let (target, after) = after.split_once(')').unwrap();
        let file = path.parent().unwrap().join(target);
        assert!(file.is_file(), "{page} shows {target}, which is missing");
        out.push(target.to_string());
        rest = after;
    }
    out
}

#[test]
fn paragraphs_are_prose_runs() {
    let md = "# T\n\nOne two\nthree.\n\n- a b\n- c\n\n| x | y |\n\n```sh\nno words here\n```\nfour\n<!-- c -->\n";
    assert_eq!(
        paragraphs(md),
        ["One two three.", "- a b", "- c", "four"].map(String::from)
    );
}

/// A file of the specification's areas (`spec/*.md`): at most this many lines.
const SPEC_FILE_MAX_LINES: usize = 300;

/// All of `spec/*.md` together (issue #74: a port author reads the spec in one sitting).
const SPEC_TOTAL_MAX_LINES: usize = 950;

/// Names the specification cites from other projects' code (INRIA's 3DGS), not ours.
const CITED_NAMES: [&str; 1] = ["cat_tensors_to_optimizer"];

/// The text files of the repository a reader or a test may follow a `SPEC.md §` reference
/// from: sources, tests, scripts and docs (not `target/`, not hidden folders, not the
/// committed audits' generated reports).
fn text_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        if name.starts_with('.') && name != ".ci" || name == "target" || name == "node_modules" {
            continue;
        }
        if p.is_dir() {
            text_files(&p, out);
        } else if ["rs", "py", "md", "sh", "toml"]
            .iter()
            .any(|x| p.extension().is_some_and(|e| e == *x))
            || p.parent()
                .and_then(Path::file_name)
                .is_some_and(|n| n == ".ci")
        {
            out.push(p);
        }
    }
}

/// The section numbers the specification defines (`## n.` and `### n.m` headings of
/// SPEC.md and `spec/*.md`).
fn spec_sections(root: &Path) -> std::collections::BTreeSet<String> {
    let mut files = vec![root.join("SPEC.md")];
    for e in std::fs::read_dir(root.join("spec")).unwrap() {
        files.push(e.unwrap().path());
    }
    let mut out = std::collections::BTreeSet::new();
    for f in files {
        for line in std::fs::read_to_string(&f).unwrap().lines() {
            let Some(rest) = line
                .strip_prefix("## ")
                .or_else(|| line.strip_prefix("### "))
            else {
                continue;
            };
            let num = rest.split_whitespace().next().unwrap_or("");
            let num = num.trim_end_matches('.');
            if num.chars().next().is_some_and(|c| c.is_ascii_digit()) {
                out.insert(num.to_string());
            }
        }
    }
    out
}

/// The specification is an index (`SPEC.md`) and area files (`spec/*.md`) of at most
/// `SPEC_FILE_MAX_LINES` lines each and `SPEC_TOTAL_MAX_LINES` together; every `SPEC.md §n`
/// or `§n.m` reference in the repository's sources, tests, scripts and docs names a section
/// one of them defines; and every test the specification names (a backticked snake_case
/// name of four or more words) exists in the code (a Rust `fn`, a Python `def`, or a field
/// or key of that name).
#[test]
fn the_spec_is_an_index_of_areas_whose_references_resolve() {
    let root = repo_root();
    let sections = spec_sections(&root);
    let mut spec_files = vec![root.join("SPEC.md")];
    let mut total = 0;
    for e in std::fs::read_dir(root.join("spec")).unwrap() {
        let p = e.unwrap().path();
        let n = std::fs::read_to_string(&p).unwrap().lines().count();
        assert!(n <= SPEC_FILE_MAX_LINES, "{} has {n} lines", p.display());
        total += n;
        spec_files.push(p);
    }
    assert!(
        total <= SPEC_TOTAL_MAX_LINES,
        "spec/*.md have {total} lines together"
    );
    let mut files = Vec::new();
    text_files(&root, &mut files);
    let mut unresolved = Vec::new();
    let mut code = String::new();
    for f in &files {
        let Ok(text) = std::fs::read_to_string(f) else {
            continue;
        };
        if f.extension().is_some_and(|e| e == "rs" || e == "py") {
            code += &text;
        }
        let mut rest = text.as_str();
        while let Some((_, after)) = rest.split_once("SPEC.md §") {
            let num: String = after
                .chars()
                .take_while(|c| c.is_ascii_digit() || *c == '.')
                .collect();
            let num = num.trim_end_matches('.');
            if !num.is_empty() && !sections.contains(num) {
                unresolved.push(format!(
                    "{}: §{num}",
                    f.strip_prefix(&root).unwrap().display()
                ));
            }
            rest = after;
        }
    }
    assert!(
        unresolved.is_empty(),
        "unresolved references: {unresolved:#?}"
    );
    let mut missing = Vec::new();
    for f in &spec_files {
        let text = std::fs::read_to_string(f).unwrap();
        for token in text.split('`').skip(1).step_by(2) {
            let snake = token
                .chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
                && token.matches('_').count() >= 3
                && !token.starts_with('_');
            if !snake || CITED_NAMES.contains(&token) {
                continue;
            }
            let found = [
                format!("fn {token}("),
                format!("def {token}("),
                format!("{token}:"),
                format!("\"{token}\""),
                format!("\\\"{token}\\\""),
                format!(".{token}"),
            ]
            .iter()
            .any(|p| code.contains(p.as_str()));
            if !found {
                missing.push(format!(
                    "{}: `{token}`",
                    f.strip_prefix(&root).unwrap().display()
                ));
            }
        }
    }
    assert!(
        missing.is_empty(),
        "named in the spec, found nowhere in the code: {missing:#?}"
    );
}
