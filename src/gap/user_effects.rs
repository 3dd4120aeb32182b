//! User hypotheses for step 2, from `effects.toml`: each a named expression
//! over the energy-map bins and the KPIs, scored like the built-in
//! candidates. The term of a tire and run is
//!
//! Σ_bins E_bin (MJ) · value(expression at that bin, θ)
//!
//! over the (surface × inner-liner temperature) map, over the (sliding
//! speed × surface temperature) map when the expression reads
//! `sliding_speed`, or over the lateral energy's (surface × inner-liner)
//! map with `energy = "lateral"`. Bin variables are the bin mid-points; a comparison counts
//! as 1 when true and 0 when false. Format: docs/gap.md.

#[cfg(test)]
use super::candidates::KpiScale;
use super::candidates::{Candidate, Feature};
use super::error::GapError;
use crate::kpi::KpiRow;
use crate::kpi::energy_maps::EnergyMaps;
use evalexpr::{Context, DefaultNumericTypes, EvalexprError, EvalexprResult, Node, Value};
use std::path::Path;
use std::sync::Arc;

/// Variables a user expression may read besides the KPI columns.
pub(crate) const BIN_VARIABLES: [&str; 4] = ["t_surface", "t_inner", "sliding_speed", "theta"];

/// The functions an expression may call: evalexpr's numeric built-ins.
/// Its string, tuple, bit and random functions have no meaning over an
/// energy map, and two of them panic on some arguments (`str::substring`
/// inside a multi-byte character, `shl` past 63 bits with overflow checks).
pub(crate) const FUNCTIONS: [&str; 34] = [
    "if",
    "min",
    "max",
    "floor",
    "round",
    "ceil",
    "math::abs",
    "math::sqrt",
    "math::cbrt",
    "math::hypot",
    "math::exp",
    "math::exp2",
    "math::ln",
    "math::log",
    "math::log2",
    "math::log10",
    "math::pow",
    "math::sin",
    "math::cos",
    "math::tan",
    "math::asin",
    "math::acos",
    "math::atan",
    "math::atan2",
    "math::sinh",
    "math::cosh",
    "math::tanh",
    "math::asinh",
    "math::acosh",
    "math::atanh",
    "math::is_nan",
    "math::is_finite",
    "math::is_infinite",
    "math::is_normal",
];

/// The longest expression read (bytes). evalexpr parses and evaluates
/// by recursion, so an expression nested some ten thousand deep overflows
/// a thread's stack, which aborts the process; this bound, and the depth
/// below, keep far from that.
const MAX_EXPRESSION_BYTES: usize = 4096;

/// The deepest expression tree read (nested brackets, functions and
/// operators: a sum of n terms is n + 1 deep). Some 8000 were evaluated on a
/// 2 MiB thread in the release build; the debug build's frames are larger.
const MAX_DEPTH: usize = 256;

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct EffectsFile {
    effect: Vec<EffectEntry>,
}

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct EffectEntry {
    name: String,
    expression: String,
    #[serde(default)]
    thresholds: Vec<f64>,
    /// "front", "rear" or "both" (default).
    #[serde(default)]
    axle: Option<String>,
    /// Only positive coefficients count (default true: a mechanism adds wear).
    #[serde(default = "yes")]
    adds_wear: bool,
    /// "total" (default) or "lateral": which friction energy the bins hold.
    #[serde(default)]
    energy: Option<String>,
}

fn yes() -> bool {
    true
}

/// One compiled user hypothesis.
#[derive(Debug)]
pub struct UserEffect {
    pub name: String,
    pub expression: String,
    pub adds_wear: bool,
    node: Node<DefaultNumericTypes>,
    /// Variables read, in a fixed order; values are filled per evaluation.
    variables: Vec<String>,
    /// Reads `sliding_speed` (the speed × surface map) rather than `t_inner`.
    speed_map: bool,
    /// Sums over the lateral energy map (`energy = "lateral"`).
    lateral: bool,
}

/// A context with the few variables an expression reads, looked up by position.
struct Vars<'a> {
    names: &'a [String],
    values: Vec<Value<DefaultNumericTypes>>,
}

impl Context for Vars<'_> {
    type NumericTypes = DefaultNumericTypes;

    fn get_value(&self, identifier: &str) -> Option<&Value<DefaultNumericTypes>> {
        self.names
            .iter()
            .position(|n| n == identifier)
            .map(|i| &self.values[i])
    }

    fn call_function(
        &self,
        identifier: &str,
        _argument: &Value<DefaultNumericTypes>,
    ) -> EvalexprResult<Value<DefaultNumericTypes>, DefaultNumericTypes> {
        Err(EvalexprError::FunctionIdentifierNotFound(
            identifier.to_string(),
        ))
    }

    fn are_builtin_functions_disabled(&self) -> bool {
        false
    }

    fn set_builtin_functions_disabled(
        &mut self,
        _disabled: bool,
    ) -> EvalexprResult<(), DefaultNumericTypes> {
        Err(EvalexprError::CustomMessage(
            "builtin functions stay enabled".into(),
        ))
    }
}

/// An expression as quoted in a message: whole up to 120 characters,
/// otherwise its first 80 and last 20 (a refused expression may be 4096
/// bytes of brackets).
fn abridged(expression: &str) -> String {
    let chars = expression.chars().count();
    if chars <= 120 {
        return expression.to_string();
    }
    let head: String = expression.chars().take(80).collect();
    let tail: String = expression.chars().skip(chars - 20).collect();
    format!("{head}…{tail}")
}

impl UserEffect {
    /// Compiles one expression, checking every variable it reads.
    pub(crate) fn compile(
        name: &str,
        expression: &str,
        adds_wear: bool,
    ) -> Result<UserEffect, String> {
        if expression.len() > MAX_EXPRESSION_BYTES {
            return Err(format!(
                "the expression is {} bytes long, more than the {MAX_EXPRESSION_BYTES} read",
                expression.len()
            ));
        }
        let node = evalexpr::build_operator_tree::<DefaultNumericTypes>(expression)
            .map_err(|e| format!("cannot parse '{}': {e}", abridged(expression)))?;
        let depth = tree_depth(&node);
        if depth > MAX_DEPTH {
            return Err(format!(
                "cannot parse '{}': nested {depth} deep, more than the {MAX_DEPTH} read",
                abridged(expression)
            ));
        }
        if let Some(f) = node
            .iter_function_identifiers()
            .find(|f| !FUNCTIONS.contains(f))
        {
            return Err(format!(
                "cannot parse '{}': unknown function '{f}' (the numeric ones: {})",
                abridged(expression),
                FUNCTIONS.join(", ")
            ));
        }
        let mut variables: Vec<String> = node
            .iter_variable_identifiers()
            .map(str::to_string)
            .collect();
        variables.sort();
        variables.dedup();
        for v in &variables {
            if !BIN_VARIABLES.contains(&v.as_str()) && !KpiRow::NUMBER_COLUMNS.contains(&v.as_str())
            {
                return Err(format!(
                    "unknown variable '{v}' (bin variables: {}; or a KPI column, docs/kpis.md)",
                    BIN_VARIABLES.join(", ")
                ));
            }
        }
        let speed_map = variables.iter().any(|v| v == "sliding_speed");
        if speed_map && variables.iter().any(|v| v == "t_inner") {
            return Err(
                "reads both sliding_speed and t_inner, which no energy map holds together".into(),
            );
        }
        // evalexpr accepts some incomplete trees ("t_surface >"): try one
        // evaluation with every variable at 1 so they fail here, not mid-run.
        let probe = Vars {
            names: &variables,
            values: vec![Value::Float(1.0); variables.len()],
        };
        match node.eval_with_context(&probe) {
            Ok(Value::Float(_) | Value::Int(_) | Value::Boolean(_)) => {}
            Ok(other) => {
                return Err(format!(
                    "cannot parse '{}': gives {other:?}, not a number",
                    abridged(expression)
                ));
            }
            Err(e) => return Err(format!("cannot parse '{}': {e}", abridged(expression))),
        }
        Ok(UserEffect {
            name: name.to_string(),
            expression: expression.to_string(),
            adds_wear,
            node,
            variables,
            speed_map,
            lateral: false,
        })
    }

    /// Sums the expression over the lateral friction energy's (surface ×
    /// inner-liner) map instead of the total energy's.
    pub(crate) fn on_lateral_energy(mut self) -> Result<UserEffect, String> {
        if self.speed_map {
            return Err("energy = \"lateral\" has no sliding-speed map: drop sliding_speed".into());
        }
        self.lateral = true;
        Ok(self)
    }

    fn value(&self, vars: &Vars) -> f64 {
        match self.node.eval_with_context(vars) {
            Ok(Value::Float(x)) => x,
            Ok(Value::Int(i)) => i as f64,
            Ok(Value::Boolean(b)) => b as u8 as f64,
            _ => f64::NAN,
        }
    }

    /// The term of one row at θ (MJ); NaN without a map or where the
    /// expression does not give a number.
    pub(crate) fn feature(&self, r: &KpiRow, maps: Option<&EnergyMaps>, theta: f64) -> f64 {
        let Some(m) = maps else {
            return f64::NAN;
        };
        let mut vars = Vars {
            names: &self.variables,
            values: self
                .variables
                .iter()
                .map(|v| match v.as_str() {
                    "theta" => Value::Float(theta),
                    "t_surface" | "t_inner" | "sliding_speed" => Value::Float(f64::NAN),
                    kpi => Value::Float(r.number(kpi).unwrap_or(f64::NAN)),
                })
                .collect(),
        };
        let slot = |name: &str| self.variables.iter().position(|v| v == name);
        let (ts, ti, vs) = (slot("t_surface"), slot("t_inner"), slot("sliding_speed"));
        let mut at = |slots: [(Option<usize>, f64); 2]| {
            for (i, x) in slots {
                if let Some(i) = i {
                    vars.values[i] = Value::Float(x);
                }
            }
            self.value(&vars)
        };
        let s = if self.lateral {
            // Maps written before the lateral map: no term, not a zero one.
            if !m.has_lateral() {
                return f64::NAN;
            }
            m.weighted_lateral_surface_inner(|t, i| at([(ts, t), (ti, i)]))
        } else if self.speed_map {
            m.weighted_speed_surface(|v, t| at([(vs, v), (ts, t)]))
        } else {
            m.weighted_surface_inner(|t, i| at([(ts, t), (ti, i)]))
        };
        s * 1e-6
    }
}

/// The depth of an expression tree, walked without recursion.
fn tree_depth(node: &Node<DefaultNumericTypes>) -> usize {
    let mut deepest = 0;
    let mut todo = vec![(node, 1)];
    while let Some((n, depth)) = todo.pop() {
        deepest = deepest.max(depth);
        todo.extend(n.children().iter().map(|c| (c, depth + 1)));
    }
    deepest
}

/// Largest `effects.toml` read: each expression is at most
/// [`MAX_EXPRESSION_BYTES`], and far fewer hypotheses than this fit a run.
const MAX_EFFECTS_BYTES: u64 = 16 << 20;

/// Reads `effects.toml` into candidates; errors name the file and the effect.
pub fn load(path: &Path) -> Result<Vec<Candidate>, GapError> {
    let file = path.display().to_string();
    let text = crate::ingest::read_text(path, MAX_EFFECTS_BYTES)?;
    let parsed: EffectsFile = toml::from_str(&text).map_err(|e| GapError::EffectsFile {
        file: file.clone(),
        message: e.to_string(),
    })?;
    parsed
        .effect
        .into_iter()
        .enumerate()
        .map(|(k, e)| {
            let err = |message: String| GapError::Effects {
                file: file.clone(),
                effect: format!("effect {} ('{}')", k + 1, e.name),
                message,
            };
            // The net under the checks: a panic in the expression library
            // while trying the expression fails this file, not the night.
            let user = crate::guard::catch_panic(|| {
                UserEffect::compile(&e.name, &e.expression, e.adds_wear)
            })
            .unwrap_or_else(|msg| Err(format!("internal error ({msg}); please report it")))
            .map_err(err)?;
            let user = match e.energy.as_deref() {
                None | Some("total") => user,
                Some("lateral") => user.on_lateral_energy().map_err(err)?,
                Some(other) => return Err(err(format!("energy '{other}' (total or lateral)"))),
            };
            let axle = match e.axle.as_deref() {
                None | Some("both") => None,
                Some("front") => Some(crate::Axle::Front),
                Some("rear") => Some(crate::Axle::Rear),
                Some(other) => {
                    return Err(err(format!("axle '{other}' (front, rear or both)")));
                }
            };
            let thresholds = if user.variables.iter().any(|v| v == "theta") {
                if e.thresholds.is_empty() {
                    return Err(err("reads theta but gives no thresholds".into()));
                }
                e.thresholds
            } else {
                vec![f64::NAN]
            };
            Ok(Candidate {
                name: format!("user: {}", e.name),
                feature: Feature::User,
                group: None,
                thresholds,
                axle,
                user: Some(Arc::new(user)),
                scopes: Vec::new(),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::candidates::{LawRow, candidate_feature, feature};

    fn map() -> EnergyMaps {
        let mut m = EnergyMaps::new();
        m.add(62.0, 92.0, 0.7, 2e6);
        m.add(88.0, 101.0, 2.2, 1e6);
        m.add(97.0, 131.0, 4.1, 0.5e6);
        m
    }

    #[test]
    fn expressions_equal_the_built_in_mechanisms() {
        let m = map();
        let r = KpiRow {
            friction_energy_j: 3.5e6,
            friction_energy_y_j: 1.4e6,
            ..Default::default()
        };
        let hot = UserEffect::compile("hot", "t_surface > theta", true).unwrap();
        let cold = UserEffect::compile(
            "cold",
            "if(0.5 * (t_surface + t_inner) < theta, 1.0, 0.0) * friction_energy_y_j / friction_energy_j",
            true,
        )
        .unwrap();
        let fast = UserEffect::compile("fast", "sliding_speed > theta", true).unwrap();
        for theta in [70.0, 85.0, 95.0, 100.0] {
            let want = feature(
                Feature::HotSurfaceEnergy,
                &r,
                Some(&m),
                theta,
                KpiScale::NONE,
            );
            assert!((hot.feature(&r, Some(&m), theta) - want).abs() < 1e-12);
            let want = feature(
                Feature::ColdTreadLateralEnergy,
                &r,
                Some(&m),
                theta,
                KpiScale::NONE,
            );
            assert!((cold.feature(&r, Some(&m), theta) - want).abs() < 1e-12);
        }
        for theta in [0.5, 2.0, 4.0] {
            let want = feature(
                Feature::FastSlidingEnergy,
                &r,
                Some(&m),
                theta,
                KpiScale::NONE,
            );
            assert!((fast.feature(&r, Some(&m), theta) - want).abs() < 1e-12);
        }
        // By hand: 1 MJ at 87.5 °C and 0.5 MJ at 97.5 °C lie above 85 °C.
        assert!((hot.feature(&r, Some(&m), 85.0) - 1.5).abs() < 1e-12);
        // On the lateral map, graining's expression is the built-in term;
        // without a lateral map there is no term.
        let lateral = UserEffect::compile("lat", "0.5 * (t_surface + t_inner) < theta", true)
            .unwrap()
            .on_lateral_energy()
            .unwrap();
        assert!(lateral.feature(&r, Some(&m), 80.0).is_nan());
        let mut ml = m.clone();
        ml.add_lateral(62.0, 92.0, 0.8e6); // bulk 77.5 °C
        ml.add_lateral(88.0, 101.0, 0.3e6); // bulk 95 °C
        for theta in [70.0, 80.0, 100.0] {
            let want = feature(
                Feature::ColdTreadLateralEnergy,
                &r,
                Some(&ml),
                theta,
                KpiScale::NONE,
            );
            assert!((lateral.feature(&r, Some(&ml), theta) - want).abs() < 1e-12);
        }
        assert!((lateral.feature(&r, Some(&ml), 80.0) - 0.8).abs() < 1e-12);
        assert!(
            UserEffect::compile("x", "sliding_speed > theta", true)
                .unwrap()
                .on_lateral_energy()
                .is_err()
        );
    }

    #[test]
    fn the_shipped_example_loads() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/effects.example.toml");
        let c = load(&path).unwrap();
        assert_eq!(c.len(), 3);
        assert!(c[2].thresholds[0].is_nan() && !c[2].adds_wear_only());
        let r = KpiRow {
            pressure_avg_pa: 2e5,
            ..Default::default()
        };
        // Σ E·v·p/1e5 by hand: (2·0.75 + 1·2.25 + 0.5·4.25) MJ·m/s × 2.
        let want = (2.0 * 0.75 + 2.25 + 0.5 * 4.25) * 2.0;
        let got = candidate_feature(
            &c[2],
            &r,
            Some(&map()),
            f64::NAN,
            KpiScale::NONE,
            LawRow::raw(&r),
        );
        assert!((got - want).abs() < 1e-12, "{got} vs {want}");
    }

    #[test]
    fn bad_files_are_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let write = |text: &str| {
            let p = dir.path().join("effects.toml");
            std::fs::write(&p, text).unwrap();
            p
        };
        let msg = |text: &str| load(&write(text)).unwrap_err().to_string();
        let e = msg(
            "[[effect]]\nname = \"a\"\nexpression = \"t_surface > 80\"\n\n[[effect]]\nname = \"b\"\nexpression = \"t_surf > 80\"\n",
        );
        assert!(
            e.contains("effects.toml") && e.contains("effect 2 ('b')") && e.contains("'t_surf'"),
            "{e}"
        );
        let e = msg("[[effect]]\nname = \"c\"\nexpression = \"t_surface > theta\"\n");
        assert!(e.contains("no thresholds"), "{e}");
        let e = msg("[[effect]]\nname = \"d\"\nexpression = \"sliding_speed * t_inner\"\n");
        assert!(e.contains("no energy map"), "{e}");
        let e = msg("[[effect]]\nname = \"e\"\nexpression = \"t_surface >\"\n");
        assert!(e.contains("cannot parse"), "{e}");
        let e = msg("[[effect]]\nname = \"f\"\nexpression = \"1\"\naxle = \"left\"\n");
        assert!(e.contains("axle 'left'"), "{e}");
        let e = msg("[[effect]]\nname = \"h\"\nexpression = \"1\"\nenergy = \"sideways\"\n");
        assert!(
            e.contains("effect 1 ('h')") && e.contains("energy 'sideways'"),
            "{e}"
        );
        let e = msg(
            "[[effect]]\nname = \"i\"\nexpression = \"sliding_speed > 2\"\nenergy = \"lateral\"\n",
        );
        assert!(e.contains("no sliding-speed map"), "{e}");
        // Not TOML of the documented shape: the file and TOML's own words
        // (line, column, what), no empty effect.
        let e = msg("[[effect]]\nname = \"j\"\nexpression = \"1\"\nexpression = \"2\"\n");
        assert!(
            e.contains("effects.toml: TOML parse error at line 4"),
            "{e}"
        );
        assert!(e.contains("duplicate key") && !e.contains(": :"), "{e}");
        // A good one: a rear-axle candidate that is zero on the fronts.
        let c = load(&write(
            "[[effect]]\nname = \"g\"\nexpression = \"t_inner > theta\"\nthresholds = [100, 120]\naxle = \"rear\"\n",
        ))
        .unwrap();
        assert_eq!(
            (c.len(), c[0].axle, c[0].thresholds.len()),
            (1, Some(crate::Axle::Rear), 2)
        );
        let front = KpiRow {
            axle: crate::Axle::Front,
            ..Default::default()
        };
        assert_eq!(
            candidate_feature(
                &c[0],
                &front,
                Some(&map()),
                100.0,
                KpiScale::NONE,
                LawRow::raw(&front)
            ),
            0.0
        );
    }

    #[test]
    fn expressions_that_would_panic_or_overflow_the_stack_are_refused() {
        let err = |e: &str| UserEffect::compile("x", e, true).unwrap_err();
        // evalexpr's `str::substring` panics inside a multi-byte character,
        // `shl` past 63 bits with overflow checks.
        let e = err("t_surface * len(str::substring(\"é\", 0, 1))");
        assert!(e.contains("unknown function 'len'"), "{e}");
        let e = err("t_surface * shl(1, 100)");
        assert!(
            e.contains("unknown function 'shl'") && e.contains("math::sqrt"),
            "{e}"
        );
        // Nested deep enough to overflow a thread's stack (the process
        // aborted at some 30 000 brackets): refused by length, or by depth
        // when within the length.
        let nest = |n: usize| format!("{}t_surface > theta{}", "(".repeat(n), ")".repeat(n));
        let e = err(&nest(100_000));
        assert!(e.contains("200017 bytes long"), "{e}");
        let e = err(&nest(1500));
        assert!(e.contains("deep, more than the 256 read"), "{e}");
        // Quoted abridged, not its 3017 bytes whole.
        assert!(e.len() < 300 && e.contains("((…))"), "{e}");
        let e = err(&format!("{}t_surface", "-".repeat(4000)));
        assert!(e.contains("deep"), "{e}");
        // Nested as a person would write it: the same term as without.
        let r = KpiRow::default();
        let bare = UserEffect::compile("x", &nest(0), true).unwrap();
        let nested = UserEffect::compile("x", &nest(20), true).unwrap();
        let sqrt = UserEffect::compile("x", "math::sqrt(t_surface) > theta", true).unwrap();
        for theta in [70.0, 90.0] {
            let want = bare.feature(&r, Some(&map()), theta);
            assert_eq!(nested.feature(&r, Some(&map()), theta), want);
            assert_eq!(sqrt.feature(&r, Some(&map()), theta.sqrt()), want);
        }
        // A sum of 255 terms is 256 deep: read, and evaluated on this
        // test's thread (2 MiB of stack) to 255 times one term.
        let one = UserEffect::compile("x", "t_surface", true).unwrap();
        let sum = vec!["t_surface"; 255].join(" + ");
        let many = UserEffect::compile("x", &sum, true).unwrap();
        let (got, want) = (
            many.feature(&r, Some(&map()), f64::NAN),
            255.0 * one.feature(&r, Some(&map()), f64::NAN),
        );
        assert!((got - want).abs() < 1e-12 * want, "{got} vs {want}");
        let e = err(&format!("{sum} + t_surface"));
        assert!(e.contains("nested 257 deep"), "{e}");
    }

    /// A random expression over the names, literals, operators and
    /// functions a user might write, evalexpr's whole built-in list
    /// included, nested up to `depth`.
    fn random_expression(rng: &mut rand_chacha::ChaCha8Rng, depth: u32) -> String {
        use rand::prelude::*;
        const NAMES: [&str; 7] = [
            "t_surface",
            "t_inner",
            "theta",
            "sliding_speed",
            "friction_energy_j",
            "pressure_avg_pa",
            "tread",
        ];
        const LITERALS: [&str; 16] = [
            "0",
            "1",
            "-1",
            "63",
            "64",
            "100",
            "9223372036854775807",
            "-9223372036854775807",
            "1e308",
            "-1e-308",
            "0.5",
            "true",
            "\"é\"",
            "\"日本\"",
            "\"\"",
            "()",
        ];
        const OPERATORS: [&str; 15] = [
            "+", "-", "*", "/", "%", "^", "==", "!=", "<", ">", "<=", ">=", "&&", "||", ",",
        ];
        const BUILT_IN: [&str; 20] = [
            "len",
            "typeof",
            "contains",
            "contains_any",
            "str::substring",
            "str::from",
            "str::trim",
            "str::to_lowercase",
            "str::to_uppercase",
            "str::regex_matches",
            "str::regex_replace",
            "bitand",
            "bitor",
            "bitxor",
            "bitnot",
            "shl",
            "shr",
            "random",
            "no_such_function",
            "math::",
        ];
        let kind = if depth == 0 {
            0
        } else {
            rng.random_range(0..7)
        };
        match kind {
            0 if rng.random_bool(0.5) => NAMES.choose(rng).unwrap().to_string(),
            0 => LITERALS.choose(rng).unwrap().to_string(),
            1 => format!("-{}", random_expression(rng, depth - 1)),
            2 => format!("!{}", random_expression(rng, depth - 1)),
            3 | 4 => {
                let a = random_expression(rng, depth - 1);
                let op = OPERATORS.choose(rng).unwrap();
                format!("{a} {op} {}", random_expression(rng, depth - 1))
            }
            5 => format!("({})", random_expression(rng, depth - 1)),
            _ => {
                let f = if rng.random_bool(0.5) {
                    BUILT_IN.choose(rng).unwrap()
                } else {
                    FUNCTIONS.choose(rng).unwrap()
                };
                // Arguments of the types the functions take, often enough
                // to reach their bodies: strings, small integers, anything.
                let args: Vec<String> = (0..rng.random_range(0..4))
                    .map(|_| match rng.random_range(0..4) {
                        0 => ["\"é\"", "\"日本\"", "\"ab\""]
                            .choose(rng)
                            .unwrap()
                            .to_string(),
                        1 => rng.random_range(0..7).to_string(),
                        _ => random_expression(rng, depth - 1),
                    })
                    .collect();
                format!("{f}({})", args.join(", "))
            }
        }
    }

    /// 20 000 random expressions (and as many cut short at a random byte):
    /// each is refused with a message or gives a term (a number or NaN) at
    /// every θ; none panics. Before the function list and the depth bound,
    /// `str::substring` inside "é" panicked here.
    #[test]
    fn random_expressions_are_refused_or_evaluated_never_panic() {
        use rand::prelude::*;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(14);
        let r = KpiRow {
            friction_energy_j: 3.5e6,
            pressure_avg_pa: 2e5,
            ..Default::default()
        };
        let m = map();
        let (mut compiled, mut panics) = (0, Vec::new());
        for _ in 0..20_000 {
            let depth = rng.random_range(1..6);
            let full = random_expression(&mut rng, depth);
            let cut = rng.random_range(0..=full.len());
            let short: String = full
                .char_indices()
                .take_while(|&(i, _)| i < cut)
                .map(|(_, c)| c)
                .collect();
            for e in [full.clone(), short] {
                let outcome = crate::guard::catch_panic(|| {
                    let Ok(user) = UserEffect::compile("x", &e, false) else {
                        return false;
                    };
                    for theta in [f64::NAN, -1.0, 80.0, 1e308] {
                        let _ = user.feature(&r, Some(&m), theta);
                    }
                    true
                });
                match outcome {
                    Ok(ok) => compiled += usize::from(ok),
                    Err(msg) => panics.push(format!("{e:?}: {msg}")),
                }
            }
        }
        eprintln!("{compiled} of 40 000 read and evaluated, the rest refused");
        assert!(
            panics.is_empty(),
            "{} panics: {:#?}",
            panics.len(),
            &panics[..panics.len().min(5)]
        );
        // The generator reaches the evaluation, not only the refusals.
        assert!(compiled > 2000, "{compiled} of 40 000 compiled");
    }
}
