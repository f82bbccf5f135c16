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
