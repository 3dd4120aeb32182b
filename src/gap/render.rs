//! The diagnosis as Markdown: what `tirewear gap` prints and writes as
//! gap.md (the JSON is the `Diagnosis` itself).

use super::baseline::PhysicsBaseline;
use super::candidates::{Feature, SET_UP_SHARE, SetUpForm, significant};
use super::report::{Diagnosis, Step, WornThrough};
use super::scoring::Score;
use crate::kpi::cpu::condition_map::{CONDITIONS, pair_conditions};
use std::fmt::Write;

/// How close to the best held-out gain a candidate must come to count as
/// one of the leads when nothing is significant: on eight or so training
/// tracks the conditions that differ between tracks in the same way fit
/// within a few hundredths of each other (docs/gap.md, "Leads").
const LEADS_WITHIN: f64 = 0.05;

/// How many leads there must be before the report names the tires most of
/// them act on: on 40 clean seasons at real-data noise, sets of 3 and 5
/// leads shared a scope by chance; the no-term seasons whose leads named
/// the planted scope had 12 to 59 (docs/gap.md, "Leads").
const LEADS_SHARING: usize = 6;

/// How many standard errors (`Score::cv_gain_se`) of its own the best
/// lead's CV gain must exceed before the report names the tires the leads
/// share: where the best gains next to nothing, the window of
/// [`LEADS_WITHIN`] around it holds half the library, and the tires most of
/// it acts on say nothing (5 of 20 clean seasons at clean noise named a
/// scope, with best gains of 0.02 to 0.10; docs/gap.md, "Leads").
const LEADS_CLEAR_SE: f64 = 2.0;

/// The candidates that best predict the held-out tracks when none is
/// significant: not findings, but where a next test should look.
#[derive(Debug, PartialEq)]
struct Leads {
    /// The candidates within [`LEADS_WITHIN`] of the best CV gain, best first.
    within: Vec<usize>,
    /// The tires most of them act on, and how many do, where that is more
    /// than half of at least [`LEADS_SHARING`].
    shared_scope: Option<(String, usize)>,
}

/// The leads among `candidates` (ranked best first by CV gain), or None
/// where no candidate improves the held-out tracks at all.
fn leads(candidates: &[Score]) -> Option<Leads> {
    let best = candidates
        .iter()
        .map(|c| c.cv_gain)
        .filter(|g| g.is_finite())
        .fold(f64::NEG_INFINITY, f64::max);
    if best <= 0.0 {
        return None;
    }
    let mut within: Vec<usize> = (0..candidates.len())
        .filter(|&i| candidates[i].cv_gain >= (best - LEADS_WITHIN).max(f64::MIN_POSITIVE))
        .collect();
    within.sort_by(|&a, &b| candidates[b].cv_gain.total_cmp(&candidates[a].cv_gain));
    let mut counts: Vec<(String, usize)> = Vec::new();
    for &i in &within {
        let scope = candidates[i].as_candidate().scope_description();
        match counts.iter_mut().find(|(s, _)| *s == scope) {
            Some((_, n)) => *n += 1,
            None => counts.push((scope, 1)),
        }
    }
    // The best must itself stand clear of no gain: near zero, every
    // candidate lies within the window of it.
    let top = &candidates[within[0]];
    let se = top.cv_gain_se();
    let clear = se.is_nan() || top.cv_gain > LEADS_CLEAR_SE * se;
    let shared_scope = counts
        .into_iter()
        .max_by_key(|(_, n)| *n)
        .filter(|(_, n)| clear && within.len() >= LEADS_SHARING && 2 * n > within.len());
    Some(Leads {
        within,
        shared_scope,
    })
}

/// The tires the leads share where Findings prints leads (no term, and
/// step 1 flagged slices): what `gap validate` compares with the planted
/// scope.
pub(crate) fn leads_scope(d: &Diagnosis) -> Option<String> {
    if !shows_leads(d) {
        return None;
    }
    leads(&d.candidates)
        .and_then(|l| l.shared_scope)
        .map(|(scope, _)| scope)
}

/// Whether Findings prints the leads: no term, and slices flagged by step 1.
fn shows_leads(d: &Diagnosis) -> bool {
    d.steps.len() <= 1 && !d.slices.is_empty()
}

/// A candidate's name as the Findings and leads say it ([`with_threshold`]).
fn named_at_threshold(c: &Score) -> String {
    with_threshold(&c.name, Some(c.feature), c.threshold)
}

/// A term's name as the Findings and leads say it: its conditions in words
/// ([`in_words`]) and its threshold in its unit, in place of θ, or for a
/// named mechanism whose name holds none, inside its parenthesis
/// ("graining (lateral energy with a cold tread: tread bulk below
/// 85.00 °C), front axle"). The tables keep the names `gap.json` has.
fn with_threshold(name: &str, feature: Option<Feature>, threshold: f64) -> String {
    let name = &in_words(name, feature);
    if !threshold.is_finite() {
        return name.to_string();
    }
    let th = feature.map_or_else(|| significant(threshold), |f| f.format_threshold(threshold));
    if name.contains('θ') {
        return name.replace('θ', &th);
    }
    match (
        feature.and_then(|f| f.threshold_phrase(threshold)),
        name.find(')'),
    ) {
        (Some(phrase), Some(close)) => format!(
            "{}: {}{}",
            &name[..close],
            phrase.replace('θ', &th),
            &name[close..]
        ),
        _ => name.to_string(),
    }
}

/// A generated candidate's name with its conditions' side-table names in
/// words ("energy with combined slip above θ" for "energy with
/// combined_slip above θ"): only the conditions the feature bins, and only
/// where the name stands as a whole word.
fn in_words(name: &str, feature: Option<Feature>) -> String {
    let conditions = match feature {
        Some(
            Feature::ConditionEnergy { condition, .. } | Feature::BandEnergy { condition, .. },
        ) => {
            vec![condition]
        }
        Some(Feature::PairEnergy { pair, .. }) => {
            let (a, b) = pair_conditions(pair);
            vec![a, b]
        }
        _ => Vec::new(),
    };
    let mut out = name.to_string();
    for c in conditions {
        out = replace_whole_word(&out, CONDITIONS[c].name, CONDITIONS[c].words);
    }
    out
}

/// `text` with every occurrence of `word` that no letter, digit or '_'
/// touches replaced by `by` (so "speed_mps" leaves "sliding_speed_mps").
fn replace_whole_word(text: &str, word: &str, by: &str) -> String {
    if word.is_empty() {
        return text.to_string();
    }
    let part_of_word = |c: Option<char>| c.is_some_and(|c| c.is_alphanumeric() || c == '_');
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(at) = rest.find(word) {
        let after = &rest[at + word.len()..];
        // `out` ends with what precedes this occurrence.
        out.push_str(&rest[..at]);
        let whole = !part_of_word(out.chars().next_back()) && !part_of_word(after.chars().next());
        out.push_str(if whole { by } else { word });
        rest = after;
    }
    out.push_str(rest);
    out
}

/// The diagnosis as Markdown (also what `tirewear gap` prints).
pub fn render_markdown(d: &Diagnosis, max_slices: usize) -> String {
    let mut s = String::from("# Sim-to-real gap\n\n");
    let _ = writeln!(s, "Baseline: {}", d.baseline);
    if let Some(p) = &d.physics {
        let _ = writeln!(s, "Calibrated on the training events: {}", describe_law(p));
    }
    write_left_out(&mut s, d);
    write_fit(&mut s, d);
    s.push_str("\n## Findings\n\n");
    write_findings(&mut s, &d.findings);
    write_slices(&mut s, d, max_slices);
    if !d.candidates.is_empty() {
        write_candidates(&mut s, d, max_slices);
        write_shrink(&mut s, d);
    }
    s
}

/// The tires left out: those the baseline cannot predict, and those worn
/// through (with the ones that enter imputed).
fn write_left_out(s: &mut String, d: &Diagnosis) {
    if !d.unpredicted.is_empty() {
        let lacking: Vec<&str> = d.unpredicted_lacking.iter().map(String::as_str).collect();
        let why = if lacking.is_empty() {
            String::new()
        } else {
            format!(
                " (none of them has {}{})",
                lacking.join(", "),
                crate::kpi::table::road_hint(&lacking)
            )
        };
        let _ = writeln!(
            s,
            "\n{} tires left out: the baseline has no prediction for them{why}: {}{}",
            d.unpredicted.len(),
            d.unpredicted
                .iter()
                .take(10)
                .cloned()
                .collect::<Vec<_>>()
                .join(", "),
            if d.unpredicted.len() > 10 {
                ", …"
            } else {
                ""
            }
        );
    }
    if !d.censored.is_empty() {
        let listed = format!(
            "{}{}",
            d.censored
                .iter()
                .take(10)
                .cloned()
                .collect::<Vec<_>>()
                .join(", "),
            if d.censored.len() > 10 { ", …" } else { "" }
        );
        let _ = if d.imputed.is_empty() {
            writeln!(
                s,
                "\n{} tires left out: tread worn through (depth readings at ≤ 5 % of the new depth), so their wear is only a lower bound: {listed}",
                d.censored.len(),
            )
        } else {
            let tail = match d.worn_through {
                WornThrough::Tobit => {
                    "E[e^r | r > r_i] of the log residuals r = ln(wear/prediction), normal with their mean and sd fitted by censored likelihood (Tobit)"
                }
                _ => {
                    "1 plus the Kaplan–Meier mean of the relative residuals wear/prediction − 1 beyond their own"
                }
            };
            writeln!(
                s,
                "\n{} tires worn through (depth readings at ≤ 5 % of the new depth), so their wear is only a lower bound: {listed}. {} of them, of the training events, enter with their wear imputed (Buckley–James: the model's prediction times {tail}); the other {} are left out.",
                d.censored.len(),
                d.imputed.len(),
                d.censored.len() - d.imputed.len(),
            )
        };
    }
}

/// The baseline's bias and RMSE on the training and testing events.
fn write_fit(s: &mut String, d: &Diagnosis) {
    let _ = writeln!(
        s,
        "\n| events | n | bias (%) | RMSE (%) |\n|---|---|---|---|"
    );
    let _ = writeln!(
        s,
        "| training | {} | {:+.3} | {:.3} |",
        d.training.n, d.training.bias_pct, d.training.rmse_pct
    );
    match &d.testing {
        Some(t) => {
            let _ = writeln!(
                s,
                "| testing ({}) | {} | {:+.3} | {:.3} |",
                d.testing_events.join(", "),
                t.n,
                t.bias_pct,
                t.rmse_pct
            );
        }
        None => {
            let _ = writeln!(s, "\n{}", no_testing_said(d));
        }
    }
}

/// Step 1: the slices flagged (at most `max_slices` listed).
fn write_slices(s: &mut String, d: &Diagnosis, max_slices: usize) {
    let _ = writeln!(
        s,
        "\n## Where the gap lies\n\n{} distinct slices tested (singly and in pairs, against the rest, t-test allowing for the residuals' correlation within events); {} survive Benjamini–Hochberg at FDR {}. Ranked by the part of the squared gap their offset accounts for (n·mean²/Σr²).\n",
        d.slices_tested,
        d.slices.len(),
        d.fdr
    );
    if !d.slices.is_empty() {
        let _ = writeln!(
            s,
            "| slice | n | mean residual (%) | vs rest (95 % CI) | effect size | p adj. | gap² accounted for | gap² held |\n|---|---|---|---|---|---|---|---|"
        );
        for t in d.slices.iter().take(max_slices) {
            let _ = writeln!(
                s,
                "| {}{} | {} | {:+.2} | {:+.2} [{:+.2}, {:+.2}] | {:+.2} | {} | {:.1} % | {:.1} % |",
                t.name,
                if t.aliases.is_empty() {
                    String::new()
                } else {
                    format!(" (same rows as {} more)", t.aliases.len())
                },
                t.n,
                t.mean_residual_pct,
                t.difference_pct,
                t.ci_pct.0,
                t.ci_pct.1,
                t.effect_size,
                p_text(t.p_adjusted),
                100.0 * t.explained_share,
                100.0 * t.share_of_squared_gap
            );
        }
        if d.slices.len() > max_slices {
            let _ = writeln!(
                s,
                "\n… and {} more (gap.json has them all).",
                d.slices.len() - max_slices
            );
        }
    }
}

/// Step 2: the candidate effects, best first (at most ten listed).
fn write_candidates(s: &mut String, d: &Diagnosis, max_slices: usize) {
    let _ = writeln!(
        s,
        "\n## Which unmodelled effect\n\nEach candidate term is refitted with the baseline's per-group energy terms on the training events, on the relative scale (rows divided by the baseline). CV gain: 1 − held-out SSE / held-out SSE of the baseline alone, whole tracks left out in turn, the threshold scanned on the training folds only. p: Freedman–Lane permutation test of the nested models (whole runs' residuals permuted within their track, wheel for wheel{}), max F over the threshold grid; road terms: F test of the tracks' severities on their road value, max F over the grid against Monte Carlo draws. p adj.: Benjamini–Hochberg within each family (within-track, road) over {} candidates, then times the number of families, so that together they hold the rate. Coefficient (physics baseline): how many times the law's abrasion per joule a mechanism adds; for a road term, % per MJ of the law's energy term per unit of its road value; for a generic KPI, % per MJ and sd. Front share: the part of the term's wear on the front axle. Acts in: the flagged slices of step 1 whose gap the fitted term follows most, with the part of the slice's mean residual it accounts for. Definitions: docs/gap.md.\n\n| candidate | threshold | coefficient | CV gain | p adj. | front share | acts in (part of the slice's mean gap) |\n|---|---|---|---|---|---|---|",
        d.exchange.also_exchanged(),
        d.candidates.len()
    );
    for c in d.candidates.iter().take(max_slices.min(10)) {
        let th = if c.threshold.is_finite() {
            c.feature.format_threshold(c.threshold)
        } else {
            "–".into()
        };
        let _ = writeln!(
            s,
            "| {}{} | {th} | {:+.4} | {:+.3} | {} | {} | {} |",
            c.name,
            if c.significant(d.fdr) {
                " **(significant)**"
            } else {
                ""
            },
            c.coefficient,
            c.cv_gain,
            p_text(c.p_adjusted),
            // A generic KPI term changes sign across rows: no share.
            if (0.0..=1.0).contains(&c.front_share) {
                format!("{:.0} %", 100.0 * c.front_share)
            } else {
                "–".to_string()
            },
            if c.acts_in.is_empty() {
                "–".to_string()
            } else {
                c.acts_in
                    .iter()
                    .map(|a| format!("{} ({:.0} %)", a.slice, 100.0 * a.share_of_offset))
                    .collect::<Vec<_>>()
                    .join("; ")
            }
        );
    }
}

/// Step 3: the fit after each added term, and the law calibrated again.
fn write_shrink(s: &mut String, d: &Diagnosis) {
    let _ = writeln!(
        s,
        "\n## How far the gap shrinks\n\nEach step adds the best significant candidate that improves the held-out tracks (significant on its own in step 2, or the mechanism already found on another axle or threshold; no generic KPI once a mechanism is in: docs/gap.md); the physics law is then calibrated again on the training events around the terms, which are refitted with it, until the calibration settles (a model baseline is refitted with the terms). Slices: the top flagged slices of step 1, in order{}.\n\n| step | training bias / RMSE (%) | testing bias / RMSE (%) | bias / RMSE in slices 1… (%) |\n|---|---|---|---|",
        d.slices
            .iter()
            .take(5)
            .enumerate()
            .map(|(i, sl)| format!("; {} = {}", i + 1, sl.name))
            .collect::<String>()
    );
    for st in &d.steps {
        let te = st.testing.map_or("–".to_string(), |t| {
            format!("{:+.3} / {:.3}", t.bias_pct, t.rmse_pct)
        });
        let sl: Vec<String> = st
            .slices
            .iter()
            .take(5)
            .map(|g| format!("{:+.2} / {:.2}", g.bias_pct, g.rmse_pct))
            .collect();
        let _ = writeln!(
            s,
            "| {} | {:+.3} / {:.3} | {te} | {} |",
            if st.added == "baseline" {
                st.added.clone()
            } else if st.threshold.is_finite() {
                format!(
                    "+ {} (θ = {}, c = {:+.4})",
                    st.added,
                    st.feature.map_or_else(
                        || significant(st.threshold),
                        |f| f.format_threshold(st.threshold)
                    ),
                    st.coefficient
                )
            } else {
                format!("+ {} (c = {:+.4})", st.added, st.coefficient)
            },
            st.training.bias_pct,
            st.training.rmse_pct,
            sl.join(", ")
        );
    }
    if let Some(p) = &d.physics_with_terms {
        let _ = writeln!(
            s,
            "\nThe law calibrated again around the terms: {}",
            describe_law(p)
        );
    }
}

/// Why the table has no testing line, and what judges a term without one.
fn no_testing_said(d: &Diagnosis) -> String {
    let why = if d.testing_events.is_empty() {
        format!(
            "No testing events: the default tests every third event and the table has {} \
             (`--test-events` names some)",
            d.training_events.len()
        )
    } else {
        format!(
            "No testing tire has a measured wear and a prediction (testing events {})",
            d.testing_events.join(", ")
        )
    };
    format!(
        "{why}, so how far the gap shrinks on events the selection never saw is not \
         measured; the held-out tracks of the cross-validation alone judge a term."
    )
}

/// The Findings of [`render_markdown`] as lines: each paragraph or numbered
/// term one line (`Diagnosis::findings`).
pub(crate) fn findings_lines(d: &Diagnosis) -> Vec<String> {
    let mut s = String::new();
    findings(&mut s, d);
    s.lines()
        .filter(|l| !l.trim().is_empty())
        .map(str::to_string)
        .collect()
}

/// `Diagnosis::findings` as Markdown: paragraphs apart, numbered terms
/// one list.
fn write_findings(s: &mut String, lines: &[String]) {
    let numbered = |l: &str| {
        l.split_once(". ")
            .is_some_and(|(n, _)| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
    };
    for (i, line) in lines.iter().enumerate() {
        if i > 0 && !(numbered(line) && numbered(&lines[i - 1])) {
            s.push('\n');
        }
        s.push_str(line);
        s.push('\n');
    }
}

/// A p-value as the tables and Findings print it: two significant digits
/// (0.44, 0.033, 0.0012), in exponent form below 0.001 (3.3e-4); an
/// adjusted p above 1 (Bonferroni over the families) reads 1.0.
fn p_text(p: f64) -> String {
    if p.is_nan() {
        return "–".into();
    }
    let p = p.min(1.0);
    if p < 1e-3 {
        return format!("{p:.1e}");
    }
    let decimals = (1 - p.log10().floor() as i32).max(1) as usize;
    format!("{p:.decimals$}")
}

/// `text` with its first letter upper-case.
fn capitalised(text: &str) -> String {
    let mut c = text.chars();
    c.next()
        .map_or(String::new(), |f| f.to_uppercase().chain(c).collect())
}

/// Findings' opening without a term: whether any candidate was
/// significant (and why none entered), and what step 1 flagged.
fn no_term(d: &Diagnosis) -> String {
    let significant: Vec<&Score> = d
        .candidates
        .iter()
        .filter(|c| c.significant(d.fdr))
        .collect();
    // Step 1 compares tires within events: a gap that differs only between
    // tracks is not a slice (docs/gap.md, "Seed 345").
    let quiet = "no slice of the tires stands out from the noise. Slices are compared within events, so a gap that differs only between tracks would show in the testing events' RMSE against the training events', not as a slice";
    if significant.is_empty() {
        return if d.slices.is_empty() {
            format!("No candidate effect is significant and {quiet}.")
        } else {
            "No candidate effect is significant: the flagged slices below stay unexplained."
                .to_string()
        };
    }
    let listed: Vec<String> = significant
        .iter()
        .take(3)
        .map(|c| {
            format!(
                "\"{}\" (p {} adjusted, CV gain {:+.3} within tracks, {:+.3} across them)",
                named_at_threshold(c),
                p_text(c.p_adjusted),
                c.cv_gain,
                c.cv_gain_across
            )
        })
        .collect();
    let more = match significant.len() {
        n if n > 3 => format!(" and {} more", n - 3),
        _ => String::new(),
    };
    let (n, verb) = match significant.len() {
        1 => ("One candidate".to_string(), "is"),
        n => (format!("{n} candidates"), "are"),
    };
    let slices = if d.slices.is_empty() {
        capitalised(quiet)
    } else {
        "The flagged slices below stay unexplained".to_string()
    };
    format!(
        "No term entered. {n} {verb} significant: {}{more}, but none both improves the prediction of held-out tracks (CV gain across tracks above 0) and passes step 3's checks. {slices}.",
        listed.join("; ")
    )
}

/// What the diagnosis found, in words: each term step 3 added with its
/// threshold, its rate against the law's and its part of the wear where it
/// acts; then the flagged slices the terms leave unexplained.
fn findings(s: &mut String, d: &Diagnosis) {
    let terms = &d.steps[1.min(d.steps.len())..];
    if terms.is_empty() {
        let _ = writeln!(s, "{}", no_term(d));
        if shows_leads(d) {
            write_leads(s, &d.candidates, d.fdr);
        }
    }
    for (t, st) in terms.iter().enumerate() {
        let _ = writeln!(s, "{}. {}", t + 1, term_finding(d, t, st));
    }
    if let Some(line) = worse_on_testing(d) {
        let _ = writeln!(s, "\n{line}");
    }
    if let Some(open) = unexplained_slices(d) {
        let _ = writeln!(
            s,
            "\nNot explained by any term (more than half of the mean residual remains): {open}."
        );
    }
}

/// Term `t` (step `t + 1`, `st`) in words: what it is, its rate against
/// the law's, its part of the wear, what to look at, the testing events'
/// RMSE and where the gap closes most.
fn term_finding(d: &Diagnosis, t: usize, st: &Step) -> String {
    // A set-up factor on one component of the energy, not the law's wear.
    let set_up_energy = match (st.feature, SetUpForm::of(st.threshold)) {
        (Some(Feature::Group), Some(SetUpForm::Energy(k))) => Some(k.energy_name()),
        _ => None,
    };
    // A condition that leaves out next to none of the energy.
    let unlimited = st.energy_share.is_some_and(|x| x >= SET_UP_SHARE);
    let advice = if st.set_up {
        " The telemetry does not show why: look at the alignment (toe, camber settings), a suspension setting or the tire batch of that group."
    } else if unlimited {
        " No condition sets it apart: the law's one rate per joule does not fit this energy on these tires as it fits the rest (how the law weighs longitudinal against lateral energy, say)."
    } else {
        ""
    };
    format!(
        "{} {}{}.{advice}{}{}",
        term_name(st, set_up_energy, unlimited),
        term_rate(d, t, st, set_up_energy.is_some()),
        term_share(d, t),
        term_testing(d, t, st),
        term_acts(d, st)
    )
}

/// The term's name, with its threshold, scope and the share of its energy
/// component it holds; a set-up effect as such.
fn term_name(st: &Step, set_up_energy: Option<&str>, unlimited: bool) -> String {
    let name = with_threshold(&st.added, st.feature, st.threshold);
    let component = st.feature.and_then(|f| f.energy_component());
    let scope = st.scope.as_deref().unwrap_or("its tires");
    let set_up = name.strip_prefix("set-up: ").map(|g| match set_up_energy {
        Some(energy) => format!("Set-up effect: the {energy} of {scope}"),
        None => format!("Set-up effect: {g}"),
    });
    match (set_up, component, st.energy_share) {
        (Some(set_up), _, _) => set_up,
        (None, Some(component), Some(x)) if unlimited => format!(
            "{} {component} of {scope} under nearly every condition (the term found, \"{name}\", holds {:.1} % of that energy)",
            if st.set_up {
                "Set-up effect: the"
            } else {
                "The"
            },
            100.0 * x
        ),
        (None, component, x) => {
            let held = match (component, x) {
                (Some(component), Some(x)) => {
                    format!(" ({:.0} % of the {component} of {scope})", 100.0 * x)
                }
                _ => String::new(),
            };
            capitalised(&name) + &held
        }
    }
}

/// The term's rate: a factor on the law's rate (or on the wear the law
/// predicts, for a set-up group of the whole law), or a coefficient; from
/// the final model, with its event-bootstrap interval.
fn term_rate(d: &Diagnosis, t: usize, st: &Step, set_up_energy: bool) -> String {
    let (c, (lo, hi)) = d
        .final_terms
        .get(t)
        .map_or((st.coefficient, (f64::NAN, f64::NAN)), |f| {
            (f.coefficient, f.ci95)
        });
    let ci = |shift: f64, digits: usize| {
        if lo.is_finite() && hi.is_finite() {
            format!(
                " (95 % interval {:.digits$} to {:.digits$})",
                shift + lo,
                shift + hi
            )
        } else {
            String::new()
        }
    };
    match st.feature {
        Some(Feature::Kpi(k)) => format!(
            "wear per MJ changes by {c:+.4} %{} per standard deviation of {k}",
            ci(0.0, 4)
        ),
        Some(Feature::Group) if set_up_energy => {
            format!("abrades {:.2}{} times the law's rate", 1.0 + c, ci(1.0, 2))
        }
        Some(Feature::Group) => format!(
            "wears {:.2}{} times what the law predicts from its telemetry",
            1.0 + c,
            ci(1.0, 2)
        ),
        Some(f) if d.physics.is_some() && !f.track_level() && f != Feature::User => format!(
            "abrades {:.2}{} times the law's rate where it acts",
            1.0 + c,
            ci(1.0, 2)
        ),
        _ => format!("coefficient {c:+.4}{}", ci(0.0, 4)),
    }
}

/// Term `t`'s part of the predicted wear of the tires it acts on, as a
/// clause (empty where there is none to give).
fn term_share(d: &Diagnosis, t: usize) -> String {
    let (part, total) = d
        .terms_wear
        .iter()
        .filter(|w| w.by_term_pct.get(t).is_some_and(|v| *v != 0.0))
        .fold((0.0, 0.0), |(a, b), w| {
            (a + w.by_term_pct[t], b + w.predicted_pct)
        });
    match 100.0 * part / total {
        x if !(total > 0.0 && x.is_finite()) => String::new(),
        x if x >= 0.0 => format!(": {x:.0} % of the predicted wear of the tires it acts on"),
        x => format!(": {:.0} % less predicted wear on the tires it acts on", -x),
    }
}

/// The testing events' RMSE before and after term `t`, with a warning
/// where it got worse.
fn term_testing(d: &Diagnosis, t: usize, st: &Step) -> String {
    match (d.steps[t].testing, st.testing) {
        (Some(a), Some(b)) if b.rmse_pct > a.rmse_pct => format!(
            " Testing-event RMSE {:.3} → {:.3} %: worse on the events the selection never saw, so it may not carry to a new event (a term can fit the training events' scatter; docs/gap.md, \"When a term makes the testing events worse\").",
            a.rmse_pct, b.rmse_pct
        ),
        (Some(a), Some(b)) => format!(
            " Testing-event RMSE {:.3} → {:.3} %.",
            a.rmse_pct, b.rmse_pct
        ),
        _ => String::new(),
    }
}

/// The slices where the term closes the gap most (empty where none were
/// measured).
fn term_acts(d: &Diagnosis, st: &Step) -> String {
    d.candidates
        .iter()
        .find(|c| c.name == st.added)
        .filter(|c| !c.acts_in.is_empty())
        .map(|c| {
            format!(
                // The change of the prediction, not the term alone: the
                // law calibrated again around the term gives back what
                // the term takes over, so other tires' slices can close
                // too (an FL term lowers the front axle's k, which an
                // FL excess had raised, and FR's overestimate goes).
                " The gap closes most (the term, and the law calibrated again around it) in: {}.",
                c.acts_in
                    .iter()
                    .map(|a| format!(
                        "{} ({:.0} % of its mean gap)",
                        a.slice,
                        100.0 * a.share_of_offset
                    ))
                    .collect::<Vec<_>>()
                    .join("; ")
            )
        })
        .unwrap_or_default()
}

/// The top five flagged slices whose mean residual the terms leave at more
/// than half, with the residual before and after; None without terms or
/// where every slice closed.
fn unexplained_slices(d: &Diagnosis) -> Option<String> {
    let (first, last) = (d.steps.first()?, d.steps.last()?);
    if d.steps.len() < 2 {
        return None;
    }
    let open: Vec<String> = d
        .slices
        .iter()
        .zip(first.slices.iter().zip(&last.slices))
        .take(5)
        .filter(|(_, (a, b))| b.bias_pct.abs() > 0.5 * a.bias_pct.abs())
        .map(|(sl, (a, b))| {
            format!(
                "{} (mean residual {:+.2} % → {:+.2} %)",
                sl.name, a.bias_pct, b.bias_pct
            )
        })
        .collect();
    (!open.is_empty()).then(|| open.join("; "))
}

/// Whether the terms together left the testing events' RMSE above the
/// baseline's: then they fit the training events without carrying to the
/// events the selection never saw, and the user is told so, in figures.
fn worse_on_testing(d: &Diagnosis) -> Option<String> {
    let (first, last) = (d.steps.first()?, d.steps.last()?);
    let (a, b) = (first.testing?, last.testing?);
    (d.steps.len() > 1 && b.rmse_pct > a.rmse_pct).then(|| {
        format!(
            "With the terms the testing events' RMSE is {:.3} % against the baseline's {:.3} %: the terms above improve the training events but not the events the selection never saw. Read them as leads to check, not as mechanisms found.",
            b.rmse_pct, a.rmse_pct
        )
    })
}

/// The leads when nothing is significant, marked as such: the candidates
/// that best predict the held-out tracks and the tires most of them act on.
fn write_leads(s: &mut String, candidates: &[Score], fdr: f64) {
    let Some(l) = leads(candidates) else {
        return;
    };
    let listed: Vec<String> = l
        .within
        .iter()
        .take(3)
        .map(|&i| {
            let c = &candidates[i];
            format!(
                "\"{}\" (CV gain {:+.3}, p {} before the adjustment, {} after)",
                named_at_threshold(c),
                c.cv_gain,
                p_text(c.p),
                p_text(c.p_adjusted)
            )
        })
        .collect();
    // A significant candidate that step 3 refused (its law no longer
    // abrading, say) leaves no term either.
    let why = if candidates.iter().any(|c| c.significant(fdr)) {
        "no term passed step 3's checks".to_string()
    } else {
        format!(
            "none of the {} candidates holds its p-value once adjusted for their number",
            candidates.len()
        )
    };
    let _ = write!(s, "\nLeads, not findings ({why}): {}", listed.join("; "));
    let more = l.within.len().saturating_sub(listed.len());
    if more > 0 {
        let _ = write!(s, "; {more} more within {LEADS_WITHIN} of the best CV gain");
    }
    match &l.shared_scope {
        Some((scope, n)) => {
            let _ = writeln!(
                s,
                ". {} act on {}: they fit these tracks' residuals about equally, so the data cannot tell which condition, if any, carries the gap there. Runs that vary those conditions at one track (a test session), or more events per track, could.",
                if *n == l.within.len() {
                    format!("All {n} of these")
                } else {
                    format!("{n} of these {}", l.within.len())
                },
                if scope == "every tire" {
                    scope.clone()
                } else {
                    format!("{scope} alone")
                }
            );
        }
        None => s.push_str(".\n"),
    }
}

/// The physics law's calibrated constants in words.
fn describe_law(p: &PhysicsBaseline) -> String {
    let ks: Vec<String> = p
        .k_pct_per_mj
        .iter()
        .map(|(c, k)| format!("{c} {k:.4}"))
        .collect();
    format!(
        "k (%/MJ) {}; {}; s = {:.3}",
        ks.join(", "),
        p.temperature_factor.describe(),
        p.skewness_coefficient
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Axle;
    use crate::gap::candidates::KpiScale;

    #[test]
    fn generated_candidates_name_their_conditions_in_words() {
        let band = Feature::BandEnergy {
            condition: 12,
            component: crate::kpi::cpu::condition_map::Component::Lateral,
        };
        assert_eq!(CONDITIONS[12].name, "t_surface_rate_kps");
        assert_eq!(
            in_words(
                "lateral energy with t_surface_rate_kps between θ, FL wheel",
                Some(band)
            ),
            "lateral energy with surface temperature's rate of change between θ, FL wheel"
        );
        // A pair: both conditions; "speed_mps" alone would not touch
        // "sliding_speed_mps".
        let p = (0..crate::kpi::cpu::condition_map::N_PAIRS)
            .find(|&p| pair_conditions(p) == (2, 10))
            .expect("the pair of combined slip and speed");
        let pair = Feature::PairEnergy {
            pair: p,
            first_above: true,
            second_above: false,
        };
        assert_eq!(
            in_words(
                "energy with (combined_slip, speed_mps) above/below θ",
                Some(pair)
            ),
            "energy with (combined slip, speed) above/below θ"
        );
        assert_eq!(
            replace_whole_word("sliding_speed_mps and speed_mps", "speed_mps", "speed"),
            "sliding_speed_mps and speed"
        );
        // Other features keep their names.
        assert_eq!(
            in_words("fz_avg_n", Some(Feature::Kpi("fz_avg_n"))),
            "fz_avg_n"
        );
    }

    #[test]
    fn named_mechanisms_say_their_threshold() {
        let graining = "graining (lateral energy with a cold tread), front axle";
        assert_eq!(
            with_threshold(graining, Some(Feature::ColdTreadLateralEnergy), 85.0),
            "graining (lateral energy with a cold tread: tread bulk below 85.00 °C), front axle"
        );
        // A road term without a hinge has no threshold to say.
        let road = "road abrasion (energy on micro-rough roads)";
        assert_eq!(
            with_threshold(road, Some(Feature::RoughRoadEnergy), 0.0),
            road
        );
        // A name with θ takes the threshold in its place.
        assert_eq!(
            with_threshold(
                "camber (energy × camber beyond θ)",
                Some(Feature::CamberEnergy),
                2.5
            ),
            "camber (energy × camber beyond 2.500 °)"
        );
        assert_eq!(with_threshold(graining, None, f64::NAN), graining);
    }

    #[test]
    fn p_values_print_with_two_significant_digits() {
        let printed: Vec<String> = [1.0, 2.5, 0.44, 0.033, 0.0012, 0.00099, 5e-4, f64::NAN]
            .into_iter()
            .map(p_text)
            .collect();
        assert_eq!(
            printed,
            [
                "1.0", "1.0", "0.44", "0.033", "0.0012", "9.9e-4", "5.0e-4", "–"
            ]
        );
    }

    fn score(name: &str, axle: Option<Axle>, cv_gain: f64) -> Score {
        Score {
            name: name.into(),
            candidate: name.into(),
            feature: Feature::Kpi("fz_avg_n"),
            axle,
            group: None,
            threshold: f64::NAN,
            coefficient: 1.0,
            cv_gain,
            cv_sse_by_fold: Vec::new(),
            cv_gain_across: cv_gain,
            p: 0.1,
            p_between: f64::NAN,
            p_adjusted: 1.0,
            front_share: f64::NAN,
            kpi_scale: KpiScale::NONE,
            acts_in: Vec::new(),
        }
    }

    /// A diagnosis without a term: the baseline's step only, `slices`
    /// flagged, six leads on the rear axle among its candidates.
    fn without_terms(slices: Vec<crate::gap::slices::Slice>) -> Diagnosis {
        use crate::gap::report::{GapSize, Step};
        let size = GapSize {
            n: 10,
            bias_pct: 0.0,
            rmse_pct: 1.0,
        };
        Diagnosis {
            baseline: "physics".into(),
            physics: None,
            physics_with_terms: None,
            training_events: vec!["E1".into()],
            testing_events: vec!["E2".into()],
            censored: Vec::new(),
            imputed: Vec::new(),
            imputed_wear_pct: Vec::new(),
            unpredicted: Vec::new(),
            unpredicted_lacking: Vec::new(),
            worn_through: Default::default(),
            exchange: Default::default(),
            training: size,
            testing: Some(size),
            fdr: 0.05,
            slices_tested: 4,
            slices,
            candidates: (0..6)
                .map(|i| score(&format!("c{i}"), Some(Axle::Rear), 0.6 - 0.001 * i as f64))
                .collect(),
            steps: vec![Step {
                added: "baseline".into(),
                feature: None,
                threshold: f64::NAN,
                coefficient: f64::NAN,
                cv_gain: f64::NAN,
                p_adjusted: f64::NAN,
                energy_share: None,
                scope: None,
                set_up: false,
                training: size,
                testing: Some(size),
                slices: Vec::new(),
            }],
            terms_wear: Vec::new(),
            final_terms: Vec::new(),
            findings: Vec::new(),
        }
    }

    /// Without a term or a flagged slice, Findings says that slices cannot
    /// show a gap between tracks, claims no agreement, and lists no leads;
    /// with a flagged slice it lists them and names the tires they share.
    #[test]
    fn without_a_term_findings_say_what_slices_cannot_show() {
        let d = without_terms(Vec::new());
        let lines = findings_lines(&d);
        assert_eq!(lines.len(), 1, "{lines:?}");
        assert!(
            lines[0].contains("differs only between tracks"),
            "{}",
            lines[0]
        );
        assert!(!lines[0].contains("agree"), "{}", lines[0]);
        assert_eq!(leads_scope(&d), None);
        let flagged = crate::gap::slices::Slice {
            name: "axle = rear".into(),
            n: 10,
            mean_residual_pct: 1.0,
            difference_pct: 2.0,
            ci_pct: (1.0, 3.0),
            effect_size: 1.0,
            p: 1e-4,
            p_adjusted: 1e-3,
            share_of_squared_gap: 0.5,
            explained_share: 0.4,
            aliases: Vec::new(),
            members: vec![true; 10],
        };
        let d = without_terms(vec![flagged]);
        let lines = findings_lines(&d);
        assert!(lines[0].ends_with("the flagged slices below stay unexplained."));
        assert!(lines[1].starts_with("Leads, not findings"), "{lines:?}");
        assert_eq!(leads_scope(&d).as_deref(), Some("the rear axle"));
    }

    /// Without testing events (a season of two events) or without testing
    /// tires to measure, gap.md says which, instead of a table whose
    /// testing line is silently missing.
    #[test]
    fn a_diagnosis_without_testing_events_says_why() {
        let mut d = without_terms(Vec::new());
        assert!(!render_markdown(&d, 5).contains("No testing"));
        d.testing = None;
        let t = render_markdown(&d, 5);
        assert!(
            t.contains("No testing tire has a measured wear and a prediction (testing events E2)"),
            "{t}"
        );
        d.testing_events.clear();
        d.training_events = vec!["E1".into(), "E3".into()];
        let t = render_markdown(&d, 5);
        assert!(
            t.contains(
                "No testing events: the default tests every third event and the table has 2 \
                 (`--test-events` names some), so how far the gap shrinks"
            ),
            "{t}"
        );
    }

    /// A significant candidate that did not enter (no gain across tracks):
    /// Findings say so, with its figures, instead of "nothing significant".
    #[test]
    fn the_report_says_how_worn_through_tires_were_imputed() {
        let mut d = without_terms(Vec::new());
        let text = |d: &Diagnosis| render_markdown(d, 5);
        d.censored = vec!["R1/FL".into(), "R2/FR".into(), "R9/RL".into()];
        assert!(text(&d).contains("3 tires left out"), "{}", text(&d));
        d.imputed = vec!["R1/FL".into(), "R2/FR".into()];
        for (how, says) in [
            (WornThrough::Impute, "Kaplan–Meier"),
            (WornThrough::Tobit, "Tobit"),
        ] {
            d.worn_through = how;
            let t = text(&d);
            assert!(
                t.contains(says) && t.contains("the other 1 are left out"),
                "{t}"
            );
        }
    }

    #[test]
    fn a_significant_candidate_that_did_not_enter_is_named() {
        let mut d = without_terms(Vec::new());
        d.candidates[2].p_adjusted = 0.026;
        d.candidates[2].cv_gain = 0.2;
        d.candidates[2].cv_gain_across = -0.05;
        let lines = findings_lines(&d);
        assert_eq!(
            lines[0],
            "No term entered. One candidate is significant: \"c2\" (p 0.026 adjusted, CV gain +0.200 within tracks, -0.050 across them), but none both improves the prediction of held-out tracks (CV gain across tracks above 0) and passes step 3's checks. No slice of the tires stands out from the noise. Slices are compared within events, so a gap that differs only between tracks would show in the testing events' RMSE against the training events', not as a slice."
        );
        for c in &mut d.candidates {
            c.p_adjusted = 0.01;
        }
        let lines = findings_lines(&d);
        assert!(lines[0].starts_with("No term entered. 6 candidates are significant"));
        assert!(lines[0].contains("\"c2\" (p 0.010 adjusted, CV gain +0.200 within tracks, -0.050 across them) and 3 more, but"), "{}", lines[0]);
    }

    /// A term that raised the testing events' RMSE is marked in its line,
    /// and the terms together, when they leave it above the baseline's, get
    /// a paragraph of their own; a term that lowered it gets neither.
    #[test]
    fn a_term_that_made_the_testing_events_worse_is_marked() {
        let mut d = without_terms(Vec::new());
        let baseline = d.steps[0].clone();
        let term = |testing_rmse: f64| crate::gap::report::Step {
            added: "KPI t_track_avg_c".into(),
            feature: Some(Feature::Kpi("t_track_avg_c")),
            testing: Some(crate::gap::report::GapSize {
                n: 10,
                bias_pct: 0.0,
                rmse_pct: testing_rmse,
            }),
            ..baseline.clone()
        };
        // Seed 8 with the imputed tires (docs/gap.md): 4.26 → 5.57 %.
        d.steps[0].testing.as_mut().unwrap().rmse_pct = 4.26;
        d.steps.push(term(5.57));
        let lines = findings_lines(&d);
        let line = lines.iter().find(|l| l.starts_with("1. ")).unwrap();
        assert!(
            line.contains(
                "Testing-event RMSE 4.260 → 5.570 %: worse on the events the selection never saw"
            ),
            "{line}"
        );
        assert!(
            lines.iter().any(|l| l.starts_with(
                "With the terms the testing events' RMSE is 5.570 % against the baseline's 4.260 %"
            )),
            "{lines:?}"
        );
        // A second term that brings it back below the baseline: only the
        // first is marked, and no paragraph.
        d.steps.push(term(4.0));
        let lines = findings_lines(&d);
        assert_eq!(lines.iter().filter(|l| l.contains(": worse on")).count(), 1);
        assert!(
            lines
                .iter()
                .any(|l| l.contains("Testing-event RMSE 5.570 → 4.000 %."))
        );
        assert!(!lines.iter().any(|l| l.starts_with("With the terms")));
    }

    /// Paragraphs apart, numbered terms one list (as gap.md always had it).
    #[test]
    fn findings_print_as_paragraphs_and_one_numbered_list() {
        let lines = |v: &[&str]| v.iter().map(|l| l.to_string()).collect::<Vec<_>>();
        let mut s = String::new();
        write_findings(&mut s, &lines(&["1. A.", "2. B.", "Not explained: x."]));
        assert_eq!(s, "1. A.\n2. B.\n\nNot explained: x.\n");
        let mut s = String::new();
        write_findings(
            &mut s,
            &lines(&["No candidate.", "Leads, not findings (1. a)."]),
        );
        assert_eq!(s, "No candidate.\n\nLeads, not findings (1. a).\n");
    }

    /// Six candidates within 0.05 of the best CV gain (0.61): four of them
    /// on the rear axle, which is more than half of six; the seventh, 0.07
    /// behind, is not a lead.
    #[test]
    fn leads_are_the_candidates_near_the_best_and_the_tires_most_act_on() {
        let c = vec![
            score("a", Some(Axle::Rear), 0.60),
            score("b", None, 0.58),
            score("c", Some(Axle::Rear), 0.61),
            score("d", Some(Axle::Rear), 0.565),
            score("e", Some(Axle::Rear), 0.54),
            score("f", Some(Axle::Front), 0.575),
            score("g", Some(Axle::Rear), 0.561),
        ];
        let l = leads(&c).unwrap();
        assert_eq!(l.within, vec![2, 0, 1, 5, 3, 6]);
        assert_eq!(l.shared_scope, Some(("the rear axle".to_string(), 4)));
        let mut s = String::new();
        write_leads(&mut s, &c, 0.05);
        assert!(s.contains("\"c\" (CV gain +0.610"), "{s}");
        assert!(s.contains("; 3 more within 0.05"), "{s}");
        assert!(s.contains("4 of these 6 act on the rear axle alone"), "{s}");
    }

    /// Half of the leads is not most of them; five leads are too few to
    /// share a scope; no positive held-out gain, no leads.
    #[test]
    fn a_scope_is_named_only_for_most_of_six_or_more_leads() {
        let axles = |n: usize, rear_every: usize| -> Vec<Score> {
            (0..n)
                .map(|i| {
                    let axle = if i % rear_every == 0 {
                        Axle::Rear
                    } else {
                        Axle::Front
                    };
                    score(&format!("{i}"), Some(axle), 0.30 - 0.001 * i as f64)
                })
                .collect()
        };
        assert_eq!(leads(&axles(6, 2)).unwrap().shared_scope, None);
        assert_eq!(leads(&axles(5, 1)).unwrap().shared_scope, None);
        assert_eq!(
            leads(&axles(6, 1)).unwrap().shared_scope,
            Some(("the rear axle".to_string(), 6))
        );
        // The best gain (0.30) within two of its standard errors of none:
        // two left-out tracks at 0.5 and 0.5 of the SSE without, 0.2 and
        // 0.5 with it (r = 0.7, u = ∓0.15, SE = √(2 · 0.045) = 0.30).
        let mut unclear = axles(6, 1);
        unclear[0].cv_sse_by_fold = vec![(0.5, 0.2), (0.5, 0.5)];
        assert!((unclear[0].cv_gain_se() - 0.09f64.sqrt()).abs() < 1e-12);
        assert_eq!(leads(&unclear).unwrap().shared_scope, None);
        // Clear of it (SE 0.03): named.
        unclear[0].cv_sse_by_fold = vec![(0.5, 0.335), (0.5, 0.365)];
        assert!(unclear[0].cv_gain_se() < 0.15);
        assert!(leads(&unclear).unwrap().shared_scope.is_some());
        let mut s = String::new();
        write_leads(&mut s, &axles(6, 1), 0.05);
        assert!(
            s.contains("All 6 of these act on the rear axle alone"),
            "{s}"
        );
        // A significant candidate that step 3 refused: the leads say so.
        let mut refused = axles(2, 1);
        refused[0].p_adjusted = 0.01;
        let mut s = String::new();
        write_leads(&mut s, &refused, 0.05);
        assert!(s.contains("(no term passed step 3's checks)"), "{s}");
        let none = vec![score("a", None, -0.01), score("b", None, f64::NAN)];
        assert_eq!(leads(&none), None);
        let mut s = String::new();
        write_leads(&mut s, &none, 0.05);
        assert!(s.is_empty());
    }
}
