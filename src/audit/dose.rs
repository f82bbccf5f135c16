//! Dose–response (SPEC.md §21.6): the audit over one parameter of the ground-truth
//! generator at several levels (`--sweep PARAM=v,…`), each level a generator of its own
//! ([`super::GeneratorKind::Dose`]); per claim Δ with its interval at each level, where Δ
//! crosses 0 (and where its interval's ends do), and one plot per claim.

use super::GeneratorKind;
use super::verdicts::{Metric, Verdict, shown_delta};
use crate::error::{Error, Result};

/// The generator parameter a sweep varies, from none (0) to full (1); every other setting
/// is the mechanisms generator's (`truth-low+hallucinating+relative`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum DoseParam {
    /// The hallucination mix `m` of unseen content (low = 0.5, high = 1).
    Hallucination,
    /// The photometric inconsistency (gain, offset, blur, shift, patches) as a fraction of
    /// the high level's.
    Photometric,
    /// The relative-depth distortion and flicker as a fraction of the high level's.
    DepthDistortion,
    /// A planted harm, the audit's positive control: the hallucination grid's level none
    /// (the mechanisms generator without hallucination: its views are chosen as the claims'
    /// are) with every generation call shifted as a whole by `t ×` [`GHOST_MAX_PX`] in a
    /// seeded direction, so that two calls generating one surface place it apart and a
    /// scene fitting both ghosts (and blurs: the gradient energy of an average of two
    /// displaced copies is at most the mean of theirs).
    Ghosting,
}

/// The ghosting sweep's shift at level 1, in pixels of the generated image.
pub const GHOST_MAX_PX: f32 = 8.0;

/// The ghosting sweep's highest level: its unit (pixels) has no natural end, and a room
/// whose unseen surfaces carry little texture needs more than [`GHOST_MAX_PX`] for two
/// displaced generations to differ (SPEC.md §21.6).
pub const GHOST_MAX_LEVEL: u8 = 200;

crate::error::text_enum!(DoseParam, "sweep parameter", {
    Hallucination => "hallucination",
    Photometric => "photometric",
    DepthDistortion => "depth_distortion",
    Ghosting => "ghosting",
});

impl DoseParam {
    /// The Holm family of a sweep: its levels together.
    pub fn family(self) -> &'static str {
        match self {
            DoseParam::Hallucination => "dose-hallucination",
            DoseParam::Photometric => "dose-photometric",
            DoseParam::DepthDistortion => "dose-depth_distortion",
            DoseParam::Ghosting => "dose-ghosting",
        }
    }

    /// The highest level, in percent: 100 (full) but for ghosting ([`GHOST_MAX_LEVEL`]).
    pub fn max_percent(self) -> u8 {
        match self {
            DoseParam::Ghosting => GHOST_MAX_LEVEL,
            _ => 100,
        }
    }
}

/// `PARAM=v1,v2,…` (levels in [0, 1], ghosting's in [0, 2]; at most two decimals) → its
/// generators.
pub fn parse_sweep(text: &str) -> Result<Vec<GeneratorKind>> {
    let bad = |why: String| Error::invalid(format!("--sweep '{text}': {why}"));
    let (param, values) = text.split_once('=').ok_or_else(|| {
        bad("expected PARAM=v1,v2,… (e.g. hallucination=0,0.25,0.5,0.75,1)".into())
    })?;
    let param: DoseParam = param.parse()?;
    let mut out = Vec::new();
    for v in values.split(',') {
        let x: f64 = v
            .trim()
            .parse()
            .map_err(|_| bad(format!("'{v}' is not a number")))?;
        let max = param.max_percent();
        let percent = crate::pipeline::config::whole_percent(x, max).ok_or_else(|| {
            bad(format!(
                "level {v} is not in [0, {}] with at most two decimals",
                f64::from(max) / 100.0
            ))
        })?;
        let g = GeneratorKind::Dose { param, percent };
        if out.contains(&g) {
            return Err(bad(format!("level {v} twice")));
        }
        out.push(g);
    }
    Ok(out)
}

/// One claim's Δ along a sweep, levels ascending.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Response {
    pub claim: String,
    pub param: String,
    /// The claim's null value (0, or −margin for "does not hurt").
    pub null: f64,
    /// Per level: the level, units judged, median Δ, the median's 95 % interval (none
    /// below 6 units), mean Δ and the verdict.
    pub levels: Vec<Level>,
    /// Where the median Δ crosses the claim's null value (linear between the two levels
    /// around the first sign change), and where the interval's lower and upper ends do:
    /// the crossing's range. `None`: no crossing within the levels.
    #[serde(with = "crate::io::json_float")]
    pub crossing: f64,
    pub crossing_range: [Option<f64>; 2],
    /// The claim's metric (for the unit of Δ in tables and plots).
    #[serde(skip)]
    pub metric: Metric,
}

#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Level {
    pub level: f64,
    pub n: usize,
    #[serde(with = "crate::io::json_float")]
    pub median: f64,
    pub ci: Option<[f64; 2]>,
    #[serde(with = "crate::io::json_float")]
    pub mean: f64,
    pub verdict: String,
}

/// The first level where `values` (paired with ascending `levels`) cross `null`, by linear
/// interpolation between the last level on one side and the first on the other (a value
/// equal to `null` is the crossing); `None` when they stay on one side (or are absent).
pub fn crossing(levels: &[f64], values: &[Option<f64>], null: f64) -> Option<f64> {
    let pts: Vec<(f64, f64)> = levels
        .iter()
        .zip(values)
        .filter_map(|(&x, v)| v.filter(|v| v.is_finite()).map(|v| (x, v - null)))
        .collect();
    for w in pts.windows(2) {
        let ((x0, y0), (x1, y1)) = (w[0], w[1]);
        if y0 == 0.0 {
            return Some(x0);
        }
        if (y0 > 0.0) != (y1 > 0.0) || y1 == 0.0 {
            return Some(x0 + (x1 - x0) * y0 / (y0 - y1));
        }
    }
    pts.first().filter(|p| p.1 == 0.0).map(|p| p.0)
}

/// The responses of every claim along every sweep present in `verdicts`.
pub fn responses(verdicts: &[Verdict]) -> Vec<Response> {
    let mut out = Vec::new();
    let mut keys: Vec<(DoseParam, &str)> = Vec::new();
    // The panel's secondary rows are tables only (SPEC.md §21.7); its primary claims and
    // their nulls are plotted.
    let plotted = |v: &&Verdict| !v.claim.metric.is_panel() || v.claim.metric.is_primary();
    for v in verdicts.iter().filter(plotted) {
        if let GeneratorKind::Dose { param, .. } = v.generator {
            let k = (param, v.claim.id);
            if !keys.contains(&k) {
                keys.push(k);
            }
        }
    }
    for (param, id) in keys {
        let mut rows: Vec<(u8, &Verdict)> = verdicts
            .iter()
            .filter(|v| v.claim.id == id)
            .filter_map(|v| match v.generator {
                GeneratorKind::Dose { param: p, percent } if p == param => Some((percent, v)),
                _ => None,
            })
            .collect();
        rows.sort_by_key(|r| r.0);
        let null = rows.first().map_or(0.0, |r| r.1.null);
        let metric = rows.first().map_or(Metric::PsnrAll, |r| r.1.claim.metric);
        let x: Vec<f64> = rows.iter().map(|r| f64::from(r.0) / 100.0).collect();
        let median: Vec<Option<f64>> = rows.iter().map(|r| Some(r.1.median_diff)).collect();
        let lo: Vec<Option<f64>> = rows.iter().map(|r| r.1.ci.map(|c| c[0])).collect();
        let hi: Vec<Option<f64>> = rows.iter().map(|r| r.1.ci.map(|c| c[1])).collect();
        out.push(Response {
            claim: id.to_string(),
            param: param.name().to_string(),
            null,
            levels: rows
                .iter()
                .map(|(p, v)| Level {
                    level: f64::from(*p) / 100.0,
                    n: v.judged,
                    median: v.median_diff,
                    ci: v.ci,
                    mean: v.mean_diff,
                    verdict: v.verdict.clone(),
                })
                .collect(),
            crossing: crossing(&x, &median, null).unwrap_or(f64::NAN),
            crossing_range: [crossing(&x, &lo, null), crossing(&x, &hi, null)],
            metric,
        });
    }
    out
}

/// The file name of a response's plot: `dose-<param>-<claim as a slug>.svg`.
pub fn plot_name(r: &Response) -> String {
    let slug: String = r
        .claim
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '-'
            }
        })
        .collect();
    let mut slug = slug.trim_matches('-').to_string();
    while slug.contains("--") {
        slug = slug.replace("--", "-");
    }
    format!("dose-{}-{slug}.svg", r.param)
}

/// A response as an SVG: Δ (in the metric's unit) against the level, the median with its interval as a
/// bar, the null value as a dashed line.
pub fn plot(r: &Response) -> String {
    let null = r.null;
    let (w, h, m) = (420.0, 260.0, 44.0);
    let mut ys: Vec<f64> = vec![null];
    for l in &r.levels {
        ys.push(l.median);
        if let Some([a, b]) = l.ci {
            ys.extend([a, b]);
        }
    }
    ys.retain(|y| y.is_finite());
    let (mut y0, mut y1) = ys
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &y| {
            (a.min(y), b.max(y))
        });
    if y1 - y0 < 1e-9 {
        (y0, y1) = (y0 - 1.0, y1 + 1.0);
    }
    // Levels run to 1, or to the sweep's highest where it goes beyond (ghosting).
    let x1 = r.levels.iter().fold(1.0f64, |a, l| a.max(l.level));
    let px = |x: f64| m + x / x1 * (w - 2.0 * m);
    let py = |y: f64| h - m - (y - y0) / (y1 - y0) * (h - 2.0 * m);
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" font-family=\"sans-serif\" font-size=\"11\">\n<text x=\"{m}\" y=\"16\">{}: Δ{} against {}</text>\n",
        r.claim,
        match r.metric.unit() {
            "" => String::new(),
            u => format!(" ({u})"),
        },
        r.param
    );
    let digits = if r.metric.unit().is_empty() { 4 } else { 2 };
    s += &format!(
        "<line x1=\"{:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"#888\" stroke-dasharray=\"4 3\"/>\n",
        px(0.0),
        py(null),
        px(x1),
        py(null)
    );
    for x in [0.0, x1 / 2.0, x1] {
        s += &format!(
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{x}</text>\n",
            px(x),
            h - m + 16.0
        );
    }
    for (y, anchor) in [(y0, y0), (y1, y1)] {
        s += &format!(
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{anchor:+.digits$}</text>\n",
            m - 4.0,
            py(y) + 4.0
        );
    }
    let mut path = String::new();
    for l in r.levels.iter().filter(|l| l.median.is_finite()) {
        if let Some([a, b]) = l.ci {
            s += &format!(
                "<line x1=\"{x:.1}\" y1=\"{:.1}\" x2=\"{x:.1}\" y2=\"{:.1}\" stroke=\"#36c\"/>\n",
                py(a),
                py(b),
                x = px(l.level)
            );
        }
        s += &format!(
            "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"3\" fill=\"#36c\"/>\n",
            px(l.level),
            py(l.median)
        );
        path += &format!(
            "{}{:.1},{:.1}",
            if path.is_empty() { "M" } else { " L" },
            px(l.level),
            py(l.median)
        );
    }
    if !path.is_empty() {
        s += &format!("<path d=\"{path}\" fill=\"none\" stroke=\"#36c\"/>\n");
    }
    s + "</svg>\n"
}

/// `audit.md`'s dose–response section (empty without a sweep).
pub fn markdown(responses: &[Response]) -> String {
    if responses.is_empty() {
        return String::new();
    }
    let mut s = "\n## Dose–response\n\nEach level of a sweep is a generator of its own (the mechanisms generator with one parameter set to the level, 0 = none, 1 = full); its claims are judged as any generator's, Holm within the sweep. *Crossing*: where the median Δ meets the claim's null value (linear between the levels around the first sign change), and in brackets where the median's interval's lower / upper ends do (–: not within the levels, or no interval below 6 seeds).\n\n| claim | parameter | level: median Δ [95 % CI] (n) | crossing |\n|---|---|---|---|\n".to_string();
    let at = |x: Option<f64>| x.map_or_else(|| "–".to_string(), |x| format!("{x:.2}"));
    for r in responses {
        let cells: Vec<String> = r
            .levels
            .iter()
            .map(|l| {
                let d = if r.metric.unit().is_empty() { 4 } else { 2 };
                let ci =
                    l.ci.map_or_else(String::new, |[a, b]| format!(" [{a:+.d$}, {b:+.d$}]"));
                format!(
                    "{:.2}: {}{ci} ({})",
                    l.level,
                    shown_delta(l.median, r.metric),
                    l.n
                )
            })
            .collect();
        let crossing = if r.crossing.is_finite() {
            format!(
                "{:.2} (interval's ends: {} / {})",
                r.crossing,
                at(r.crossing_range[0]),
                at(r.crossing_range[1])
            )
        } else {
            "none within the levels".into()
        };
        s += &format!(
            "| {} | {} | {} | {crossing} |\n",
            r.claim,
            r.param,
            cells.join("; ")
        );
    }
    for r in responses {
        s += &format!("\n![{} against {}]({})\n", r.claim, r.param, plot_name(r));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::audit::Variant;

    #[test]
    fn crossings_interpolate_between_the_levels_around_the_first_sign_change() {
        let x = [0.0, 0.25, 0.5, 0.75, 1.0];
        let v = |d: [f64; 5]| d.map(Some);
        assert_eq!(
            crossing(&x, &v([2.0, 1.0, -1.0, -2.0, -3.0]), 0.0),
            Some(0.375)
        );
        assert_eq!(
            crossing(&x, &v([2.0, 1.0, 0.0, -2.0, -3.0]), 0.0),
            Some(0.5)
        );
        assert_eq!(crossing(&x, &v([2.0, 1.0, 0.5, 0.2, 0.1]), 0.0), None);
        // Against a non-inferiority margin.
        assert_eq!(
            crossing(&x, &v([0.0, -0.1, -0.3, -1.0, -2.0]), -0.2),
            Some(0.375)
        );
        // Missing levels are skipped.
        let gaps = [Some(1.0), None, Some(-1.0), None, None];
        assert_eq!(crossing(&x, &gaps, 0.0), Some(0.25));
    }

    #[test]
    fn sweeps_parse_into_named_generators_and_bad_ones_are_clear_errors() {
        let g = parse_sweep("hallucination=0,0.25,0.5,0.75,1").unwrap();
        let names: Vec<String> = g.iter().map(|g| g.name()).collect();
        assert_eq!(
            names,
            [
                "dose-hallucination-0",
                "dose-hallucination-25",
                "dose-hallucination-50",
                "dose-hallucination-75",
                "dose-hallucination-100"
            ]
        );
        for n in &names {
            assert_eq!(&GeneratorKind::by_name(n).unwrap().name(), n);
        }
        // Ghosting's unit is pixels, with levels up to 2 (16 px).
        let g = parse_sweep("ghosting=1,2").unwrap();
        let names: Vec<String> = g.iter().map(|g| g.name()).collect();
        assert_eq!(names, ["dose-ghosting-100", "dose-ghosting-200"]);
        assert_eq!(GeneratorKind::by_name("dose-ghosting-200").unwrap(), g[1]);
        for bad in [
            "dose-hallucination-050",
            "dose-hallucination-101",
            "dose-ghosting-201",
            "dose-colour-10",
        ] {
            assert!(GeneratorKind::by_name(bad).is_err(), "{bad}");
        }
        for (bad, says) in [
            ("hallucination", "PARAM=v1"),
            ("colour=0.5", "unknown sweep parameter"),
            ("photometric=1.5", "not in [0, 1]"),
            ("photometric=0.125", "two decimals"),
            ("depth_distortion=0.5,0.5", "twice"),
            ("photometric=x", "not a number"),
            ("ghosting=2.5", "not in [0, 2]"),
        ] {
            let e = parse_sweep(bad).unwrap_err().to_string();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }

    /// The sweep's levels are the mechanisms generator with one parameter moved: at the
    /// low level's value it is that generator's configuration exactly, at 0 the parameter
    /// is off.
    #[test]
    fn sweep_levels_move_one_parameter_of_the_mechanisms_generator() {
        use crate::pipeline::{Hallucination, Inconsistency, Level, PipelineConfig};
        let cfg = super::super::AuditConfig::quick();
        let at = |g: GeneratorKind| cfg.pipeline_config(g, Variant::Full, 0).unwrap();
        let base = at(GeneratorKind::Hallucinating(Level::Low));
        let dose = |param, percent| at(GeneratorKind::Dose { param, percent });
        assert_eq!(dose(DoseParam::Hallucination, 50), base);
        assert_eq!(
            dose(DoseParam::Hallucination, 0).hallucination,
            Hallucination::None
        );
        let h = dose(DoseParam::Hallucination, 25).hallucination;
        assert_eq!((h.mix(), h.objects()), (0.25, 0));
        let h = dose(DoseParam::Hallucination, 75).hallucination;
        assert_eq!((h.mix(), h.objects()), (0.75, 2));
        assert_eq!(
            (Hallucination::Low.objects(), Hallucination::High.objects()),
            (1, 3)
        );
        let p = dose(DoseParam::Photometric, 100).inconsistency;
        let high = Inconsistency::HIGH;
        assert_eq!(
            (p.gain, p.shift_px, p.patches),
            (high.gain, high.shift_px, high.patches)
        );
        assert_eq!(p.depth_distortion, base.inconsistency.depth_distortion);
        let d = dose(DoseParam::DepthDistortion, 0).inconsistency;
        assert_eq!((d.depth_flicker, d.depth_distortion), (0.0, 0.0));
        assert_eq!(d.gain, base.inconsistency.gain);
        // The planted harm: the grid's level none with the shift alone moved.
        let none = dose(DoseParam::Hallucination, 0);
        let g = dose(DoseParam::Ghosting, 50);
        assert_eq!(
            g.inconsistency,
            Inconsistency {
                shift_px: 0.5 * super::GHOST_MAX_PX,
                ..none.inconsistency
            }
        );
        assert_eq!(
            PipelineConfig {
                inconsistency: none.inconsistency,
                ..g
            },
            none
        );
        // In a configuration file: names for the named levels, numbers between.
        let text = |h: Hallucination| serde_json::to_string(&h).unwrap();
        assert_eq!(text(Hallucination::Low), "\"low\"");
        assert_eq!(text(Hallucination::Percent(25)), "0.25");
        let read = |s: &str| serde_json::from_str::<Hallucination>(s);
        assert_eq!(read("0.5").unwrap(), Hallucination::Low);
        assert_eq!(read("0.25").unwrap(), Hallucination::Percent(25));
        assert!(read("1.5").is_err() && read("\"some\"").is_err());
    }
}
