//! Fitted models as versioned JSON files (`tirewear fit` writes them,
//! `tirewear predict` and `tirewear gap --baseline` read them): the feature
//! names and units, the normalisation, the coefficients or weights, the
//! settings and the indicators. Format: docs/models.md.

use super::ModelError;
use super::interval::{IntervalLevel, conformal_half_width, conformal_rows_needed};
use super::metrics::Metrics;
use super::network::{NetworkFit, NetworkSettings};
use super::ols::OlsFit;
use super::pca::PcaFit;
use super::physical::{AxleAnalysis, PHYSICAL_INPUTS, inputs_of};
use crate::kpi::{KpiRow, table::unit};
use std::path::Path;

pub(crate) const MODEL_FORMAT: &str = "tirewear-model";
pub(crate) const MODEL_VERSION: u32 = 2;

/// A column with its unit.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Feature {
    pub name: String,
    pub unit: String,
}

impl Feature {
    pub fn of(name: &str) -> Feature {
        Feature {
            name: name.to_string(),
            unit: unit(name).to_string(),
        }
    }
}

/// One line of a performance table (paper tables 8, 9, 11).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Indicators {
    /// e.g. "Training", "Testing", "Rear—Testing".
    pub label: String,
    pub metrics: Metrics,
    /// The share (0–1) of these tires whose measured wear lies inside its
    /// 95 % prediction interval ([`SavedModel::predict_row_within`]): near
    /// 0.95 where the model's error holds on these events. None in files
    /// before 2026-12-02 (the network's before 2026-12-03).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inside_95_interval: Option<f64>,
    /// The same for the 95 % new-event interval
    /// ([`SavedModel::event_interval_around`]). None in files before
    /// 2026-12-03 and for a model without event errors.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inside_95_event_interval: Option<f64>,
}

/// The training tires' errors when their event was left out of the fit
/// (with more than `fit::MAX_EVENT_FOLDS` training events, their fold):
/// |y − ŷ₋ₑ| in % of the tread, per axle, ascending. The calibration
/// scores of the new-event interval.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EventErrors {
    /// The training events whose tires are among the scores (those whose
    /// fold's refit succeeded), sorted.
    pub events: Vec<String>,
    /// The refits: one per training event, or `fit::MAX_EVENT_FOLDS` folds
    /// of them.
    pub folds: usize,
    pub front: Vec<f64>,
    pub rear: Vec<f64>,
}

impl EventErrors {
    fn of(&self, axle: crate::Axle) -> &[f64] {
        match axle {
            crate::Axle::Front => &self.front,
            crate::Axle::Rear => &self.rear,
        }
    }
}

/// What was fitted, by method.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "method", rename_all = "lowercase")]
pub enum ModelBody {
    Ffnn {
        settings: NetworkSettings,
        network: NetworkFit,
    },
    Pca {
        /// Candidates dropped as correlated with an input kept (target not looked at).
        dropped_correlated: Vec<String>,
        pca: PcaFit,
        /// OLS on the kept component scores PC1..PCk.
        regression: OlsFit,
    },
    Physical {
        front: AxleAnalysis,
        rear: AxleAnalysis,
    },
}

/// A fitted model as saved.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SavedModel {
    pub format: String,
    pub version: u32,
    pub tirewear_version: String,
    pub target: Feature,
    /// Input columns, in the order the model reads them.
    pub features: Vec<Feature>,
    pub training_events: Vec<String>,
    pub testing_events: Vec<String>,
    pub indicators: Vec<Indicators>,
    pub model: ModelBody,
    /// The new-event interval's scores; None in files before 2026-12-03
    /// and for a fit on one training event.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub event_errors: Option<EventErrors>,
}

impl SavedModel {
    pub fn method(&self) -> &'static str {
        match self.model {
            ModelBody::Ffnn { .. } => "ffnn",
            ModelBody::Pca { .. } => "pca",
            ModelBody::Physical { .. } => "physical",
        }
    }

    /// Predicted mean wear (%) of one row; the physical model picks the
    /// regression of the row's axle.
    pub fn predict_row(&self, r: &KpiRow) -> Result<f64, ModelError> {
        let (p, _) = self.predict_row_within(r, None)?;
        Ok(p)
    }

    /// Predicted mean wear (%) of one row and, given a level, its prediction
    /// interval (lower, upper bound in %) where the model has one: the
    /// regressions' of the PCA and physical methods
    /// ([`OlsFit::prediction_interval`]), the network's split-conformal one
    /// ([`NetworkFit::prediction_interval`]); [`SavedModel::why_no_intervals`]
    /// says why a model has none.
    pub fn predict_row_within(
        &self,
        r: &KpiRow,
        level: Option<IntervalLevel>,
    ) -> Result<(f64, Option<(f64, f64)>), ModelError> {
        let x: Vec<f64> = self
            .features
            .iter()
            .map(|f| {
                r.number(&f.name)
                    .ok_or_else(|| ModelError::Invalid(format!("no KPI column '{}'", f.name)))
            })
            .collect::<Result<_, _>>()?;
        if let Some((f, v)) = self.features.iter().zip(&x).find(|(_, v)| !v.is_finite()) {
            return Err(ModelError::Invalid(format!(
                "run {} wheel {}: input '{}' is {v}",
                r.run, r.wheel, f.name
            )));
        }
        let regression = |ols: &OlsFit, x: &[f64]| {
            let p = ols.predict_one(x);
            (p, level.and_then(|l| ols.prediction_interval(x, l)))
        };
        let (p, interval) = match &self.model {
            ModelBody::Ffnn { network, .. } => (
                network.net.predict_one(&x),
                level.and_then(|l| network.prediction_interval(&x, l)),
            ),
            ModelBody::Pca {
                pca,
                regression: ols,
                ..
            } => regression(ols, &pca.transform(&[x])[0]),
            ModelBody::Physical { front, rear } => match r.axle {
                crate::Axle::Front => regression(&front.regression, &inputs_of(r)),
                crate::Axle::Rear => regression(&rear.regression, &inputs_of(r)),
            },
        };
        if !p.is_finite() {
            return Err(ModelError::Invalid(format!(
                "run {} wheel {}: the prediction is {p} (inputs far outside the training range)",
                r.run, r.wheel
            )));
        }
        Ok((p, interval))
    }

    /// The `level` new-event interval around a prediction `p` (%) of a tire
    /// on `axle`: split conformal, p ± the ⌈(n + 1)·level⌉-th smallest of
    /// the n training tires' leave-one-event-out errors on that axle
    /// ([`EventErrors`]). Where the model's own interval is for a new tire
    /// at the training events, this one is for a tire at an event the fit
    /// did not see, the shift of a new track included. None without the
    /// scores or with too few for the level.
    pub fn event_interval_around(
        &self,
        p: f64,
        axle: crate::Axle,
        level: IntervalLevel,
    ) -> Option<(f64, f64)> {
        let half = conformal_half_width(self.event_errors.as_ref()?.of(axle), level)?;
        (half.is_finite() && p.is_finite()).then_some((p - half, p + half))
    }

    /// Why the model gives no `level` new-event intervals (on some axle),
    /// or None when it does.
    pub fn why_no_event_intervals(&self, level: IntervalLevel) -> Option<String> {
        let Some(errors) = &self.event_errors else {
            return Some(
                "the model was saved before tirewear kept its leave-one-event-out errors, or \
                 was fitted on one training event"
                    .into(),
            );
        };
        let needed = conformal_rows_needed(level);
        let short: Vec<String> = [crate::Axle::Front, crate::Axle::Rear]
            .into_iter()
            .filter(|&a| conformal_half_width(errors.of(a), level).is_none())
            .map(|a| format!("{} {} of {needed}", a, errors.of(a).len()))
            .collect();
        (!short.is_empty()).then(|| {
            format!(
                "too few training tires' errors for this level ({}; a lower --interval)",
                short.join(", ")
            )
        })
    }

    /// Why the model gives no `level` prediction intervals, or None when it
    /// does: a regression saved without its (XᵀX)⁻¹ (before 2026-12-02), a
    /// network saved without its validation errors (before 2026-12-03), or
    /// one with too few validation rows for the level.
    pub fn why_no_intervals(&self, level: IntervalLevel) -> Option<String> {
        let again = "; fit it again to have them";
        let regression_without = match &self.model {
            ModelBody::Ffnn { network, .. } => {
                let scores = match &network.validation_abs_residuals {
                    None => {
                        return Some(format!(
                            "the network was saved before tirewear kept its validation errors{again}"
                        ));
                    }
                    Some(scores) => scores,
                };
                return conformal_half_width(scores, level).is_none().then(|| {
                    format!(
                        "the network kept {} validation rows, and a conformal interval at \
                         this level needs {} (a lower --interval, or more training rows)",
                        scores.len(),
                        conformal_rows_needed(level)
                    )
                });
            }
            ModelBody::Pca { regression, .. } => regression.xtx_inverse.is_none(),
            ModelBody::Physical { front, rear } => {
                front.regression.xtx_inverse.is_none() || rear.regression.xtx_inverse.is_none()
            }
        };
        regression_without
            .then(|| format!("the model was saved before tirewear kept (XᵀX)⁻¹{again}"))
    }

    /// The file's text: the model as pretty JSON, then, as its last field,
    /// `data_crc32`: the CRC-32 of that JSON without the field
    /// (`ingest::checksum::seal_json`; docs/models.md, "Checksum").
    pub(crate) fn to_json(&self) -> String {
        let body = serde_json::to_string_pretty(self).expect("model serialises");
        crate::ingest::checksum::seal_json(&body)
    }

    /// Writes the model atomically.
    pub fn save(&self, path: &Path) -> std::io::Result<()> {
        crate::atomic::write_bytes(path, self.checked_json()?.as_bytes())
    }

    /// [`SavedModel::to_json`], refused unless [`SavedModel::load`] would
    /// read it back: a number a model cannot hold (NaN where `load` wants a
    /// finite one) is an error now, not a file that nothing reads later.
    fn checked_json(&self) -> std::io::Result<String> {
        let text = self.to_json();
        serde_json::from_str::<SavedModel>(&text)
            .map_err(|e| e.to_string())
            .and_then(|back| back.check_shapes())
            .map_err(|why| {
                std::io::Error::other(format!(
                    "the {} model would not read back ({why}); this is a tirewear bug, \
                     please report it with the KPI table",
                    self.method()
                ))
            })?;
        Ok(text)
    }

    /// Reads a model file, refusing other formats and newer versions.
    pub fn load(path: &Path) -> Result<SavedModel, ModelError> {
        let file = |what: String| ModelError::File {
            path: path.display().to_string(),
            what,
        };
        let text = crate::ingest::read_text(path, crate::ingest::MAX_JSON_BYTES).map_err(|e| {
            ModelError::Io {
                path: path.display().to_string(),
                message: crate::ingest::unnamed(path, &e) + &models_in(path),
            }
        })?;
        let head: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| file(format!("not JSON: {e}")))?;
        if head["format"] != MODEL_FORMAT {
            return Err(file(format!(
                "not a tirewear model (field \"format\" is {}, expected \"{MODEL_FORMAT}\")",
                head["format"]
            )));
        }
        match head["version"].as_u64() {
            Some(v) if (1..=u64::from(MODEL_VERSION)).contains(&v) => {}
            v => {
                return Err(file(format!(
                    "model format version {v:?}, this tirewear reads versions 1 to {MODEL_VERSION}"
                )));
            }
        }
        if let Some(why) = crate::ingest::checksum::json_mismatch(&text, &head, "tirewear fit") {
            return Err(file(why));
        }
        let model: SavedModel = serde_json::from_str(&text).map_err(|e| file(e.to_string()))?;
        model.check_shapes().map_err(file)?;
        Ok(model)
    }

    /// Refuses a model whose parts do not fit together (a damaged or
    /// hand-edited file), which would otherwise index out of bounds or
    /// predict wrong numbers without a word: every array a prediction reads
    /// against the features and the layer sizes, its numbers finite and the
    /// standard deviations positive. The first problem, by its field.
    fn check_shapes(&self) -> Result<(), String> {
        if let Some(errors) = &self.event_errors {
            ascending_errors("event_errors.front", &errors.front)?;
            ascending_errors("event_errors.rear", &errors.rear)?;
        }
        let d = self.features.len();
        match &self.model {
            ModelBody::Ffnn { network, .. } => {
                let net = &network.net;
                let at = "model.network.net";
                if net.inputs != d {
                    return Err(format!(
                        "{at}.inputs is {}, the model has {d} features",
                        net.inputs
                    ));
                }
                for (name, h) in [("hidden1", net.hidden1), ("hidden2", net.hidden2)] {
                    // Sizes the weights' count is computed from: a damaged
                    // one must not overflow it.
                    if !(1..=MAX_HIDDEN).contains(&h) {
                        return Err(format!("{at}.{name} is {h}, a layer of 1 to {MAX_HIDDEN}"));
                    }
                }
                let weights = super::ffnn::n_weights(d, net.hidden1, net.hidden2);
                let why = format!(
                    "{d} inputs, hidden layers of {} and {}",
                    net.hidden1, net.hidden2
                );
                length(&format!("{at}.weights"), &net.weights, weights, &why)?;
                length(
                    &format!("{at}.input_mean"),
                    &net.input_mean,
                    d,
                    "the features",
                )?;
                length(
                    &format!("{at}.input_std"),
                    &net.input_std,
                    d,
                    "the features",
                )?;
                positive(&format!("{at}.input_std"), &net.input_std)?;
                finite(&format!("{at}.target_mean"), &[net.target_mean])?;
                positive(&format!("{at}.target_std"), &[net.target_std])?;
                conformal_scores(network)
            }
            ModelBody::Pca {
                pca, regression, ..
            } => {
                let at = "model.pca";
                if pca.inputs.iter().ne(self.features.iter().map(|f| &f.name)) {
                    return Err(format!("{at}.inputs are not the model's features"));
                }
                length(&format!("{at}.means"), &pca.means, d, "the features")?;
                length(&format!("{at}.stds"), &pca.stds, d, "the features")?;
                positive(&format!("{at}.stds"), &pca.stds)?;
                if pca.kept == 0 || pca.kept > pca.loadings.len() {
                    return Err(format!(
                        "{at}.kept is {} with {} components in {at}.loadings",
                        pca.kept,
                        pca.loadings.len()
                    ));
                }
                for (c, a) in pca.loadings[..pca.kept].iter().enumerate() {
                    length(&format!("{at}.loadings[{c}]"), a, d, "the features")?;
                }
                let why = "an intercept and one per component kept";
                length("model.regression.coef", &regression.coef, pca.kept + 1, why)?;
                interval_parts("model.regression", regression, why)
            }
            ModelBody::Physical { front, rear } => {
                let why = "an intercept and one per physical input";
                for (axle, a) in [("front", front), ("rear", rear)] {
                    let field = format!("model.{axle}.regression.coef");
                    length(&field, &a.regression.coef, PHYSICAL_INPUTS.len() + 1, why)?;
                    interval_parts(&format!("model.{axle}.regression"), &a.regression, why)?;
                }
                Ok(())
            }
        }
    }

    /// Checks a KPI table's columns and units against the model's features;
    /// every mismatch is named. `units`: column name → unit stated by the
    /// table (None when the table states none: the documented unit is assumed).
    pub fn check_columns(&self, units: &[(String, Option<String>)]) -> Result<(), ModelError> {
        let mut problems = Vec::new();
        for f in self.features.iter().chain([&self.target]) {
            match units.iter().find(|(n, _)| *n == f.name) {
                None if f.name == self.target.name => {}
                None => problems.push(format!("column '{}' is missing", f.name)),
                Some((_, Some(u))) if *u != f.unit => problems.push(format!(
                    "column '{}' is in {u}, the model was fitted in {}",
                    f.name, f.unit
                )),
                Some(_) => {}
            }
        }
        if problems.is_empty() {
            Ok(())
        } else {
            Err(ModelError::Invalid(format!(
                "the table does not match the {} model: {}",
                self.method(),
                problems.join("; ")
            )))
        }
    }
}

/// Largest hidden layer a saved network may declare (`fit` tries up to the
/// number of inputs plus 4).
const MAX_HIDDEN: usize = 4096;

/// What a regression's prediction interval reads, where it has one:
/// (XᵀX)⁻¹ with (k + 1)² finite numbers for k + 1 coefficients (`why`:
/// what sets their count), σ² finite and not negative, and at least one
/// residual degree of freedom.
fn interval_parts(at: &str, ols: &OlsFit, why: &str) -> Result<(), String> {
    let Some(inv) = &ols.xtx_inverse else {
        return Ok(());
    };
    let k1 = ols.coef.len();
    length(
        &format!("{at}.xtx_inverse"),
        inv,
        k1 * k1,
        &format!("the square of {k1}: {why}"),
    )?;
    finite(&format!("{at}.sigma2"), &[ols.sigma2])?;
    if ols.sigma2 < 0.0 {
        return Err(format!("{at}.sigma2 is {}, a variance", ols.sigma2));
    }
    if ols.df_resid == 0 {
        return Err(format!("{at}.df_resid is 0: no prediction interval"));
    }
    Ok(())
}

/// What the network's conformal interval reads, where it has it: one
/// |residual| per validation row, finite, not negative and ascending (the
/// interval takes the k-th by position).
fn conformal_scores(network: &NetworkFit) -> Result<(), String> {
    let Some(scores) = &network.validation_abs_residuals else {
        return Ok(());
    };
    let at = "model.network.validation_abs_residuals";
    length(
        at,
        scores,
        network.validation_rows,
        "one per validation row (model.network.validation_rows)",
    )?;
    ascending_errors(at, scores)
}

/// Conformal scores as an interval reads them: finite, not negative and
/// ascending (it takes the k-th by position).
fn ascending_errors(at: &str, scores: &[f64]) -> Result<(), String> {
    finite(at, scores)?;
    if let Some(i) = scores.iter().position(|&v| v < 0.0) {
        return Err(format!("{at}[{i}] is {}, an absolute error", scores[i]));
    }
    if let Some(i) = (1..scores.len()).find(|&i| scores[i] < scores[i - 1]) {
        return Err(format!(
            "{at}[{i}] is {}, below the {} before it: the errors must be ascending",
            scores[i],
            scores[i - 1]
        ));
    }
    Ok(())
}

/// `values` has `want` numbers (`why`: what sets that) and each is finite.
fn length(field: &str, values: &[f64], want: usize, why: &str) -> Result<(), String> {
    if values.len() != want {
        return Err(format!(
            "{field} has {} values, {want} expected ({why})",
            values.len()
        ));
    }
    finite(field, values)
}

fn finite(field: &str, values: &[f64]) -> Result<(), String> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(format!("{field}[{i}] is {}", values[i])),
        None => Ok(()),
    }
}

fn positive(field: &str, values: &[f64]) -> Result<(), String> {
    finite(field, values)?;
    match values.iter().position(|&v| v <= 0.0) {
        Some(i) => Err(format!(
            "{field}[{i}] is {}, a standard deviation must be positive",
            values[i]
        )),
        None => Ok(()),
    }
}

/// For a model path that is a folder (`predict models …`), the model files
/// `fit` writes that it holds ("; it holds DIR/physical.json, …").
fn models_in(path: &Path) -> String {
    if !path.is_dir() {
        return String::new();
    }
    let held: Vec<String> = ["ffnn", "pca", "physical"]
        .iter()
        .map(|m| path.join(format!("{m}.json")))
        .filter(|p| p.is_file())
        .map(|p| p.display().to_string())
        .collect();
    if held.is_empty() {
        return "; a model is a JSON file `tirewear fit` writes".to_string();
    }
    format!("; give one of the models in it: {}", held.join(", "))
}

/// Journal of the model files' commit in their folder (`atomic::OutputSet`).
pub const MODELS_JOURNAL: &str = ".models.journal";

/// Writes the models of one fit to `dir` as `<method>.json`; they become
/// visible together (`atomic::OutputSet`), so a fit killed while writing
/// leaves the previous fit's files, not a mix of two fits.
pub fn save_all(models: &[SavedModel], dir: &Path) -> std::io::Result<Vec<std::path::PathBuf>> {
    std::fs::create_dir_all(dir)?;
    let paths: Vec<_> = models
        .iter()
        .map(|m| dir.join(format!("{}.json", m.method())))
        .collect();
    let texts: Vec<String> = models
        .iter()
        .map(SavedModel::checked_json)
        .collect::<std::io::Result<_>>()?;
    let files: Vec<_> = paths
        .iter()
        .zip(&texts)
        .map(|(p, t)| (p.as_path(), t.as_bytes()))
        .collect();
    crate::atomic::write_set(&dir.join(MODELS_JOURNAL), &files)?;
    Ok(paths)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unreadable_and_foreign_model_files_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("none.json");
        assert!(matches!(
            SavedModel::load(&missing),
            Err(ModelError::Io { path, .. }) if path.ends_with("none.json")
        ));
        let foreign = dir.path().join("other.json");
        std::fs::write(&foreign, r#"{"format": "something-else", "version": 1}"#).unwrap();
        let e = SavedModel::load(&foreign).unwrap_err();
        assert!(matches!(&e, ModelError::File { .. }), "{e:?}");
        assert!(e.to_string().contains("not a tirewear model"), "{e}");
        std::fs::write(&foreign, "not json").unwrap();
        assert!(
            SavedModel::load(&foreign)
                .unwrap_err()
                .to_string()
                .contains("not JSON")
        );
    }

    /// A model, an `effects.toml` or a report's JSON given as a device or
    /// a FIFO is refused before it is read: `/dev/zero` was read until the
    /// memory ran out, and a FIFO's open waited for a writer (`predict`,
    /// `gap --effects`, `gap --baseline`, `report --bench` hung).
    /// `predict models …`: the folder is named for what it is, with the
    /// models in it to choose from.
    #[test]
    fn a_folder_given_as_a_model_names_the_models_it_holds() {
        let dir = tempfile::tempdir().unwrap();
        let e = SavedModel::load(dir.path()).unwrap_err().to_string();
        assert!(
            e.contains("is a folder") && e.contains("a model is a JSON file"),
            "{e}"
        );
        std::fs::write(dir.path().join("physical.json"), "{}").unwrap();
        std::fs::write(dir.path().join("pca.json"), "{}").unwrap();
        let e = SavedModel::load(dir.path()).unwrap_err().to_string();
        let pca = dir.path().join("pca.json").display().to_string();
        let physical = dir.path().join("physical.json").display().to_string();
        assert!(
            e.ends_with(&format!("give one of the models in it: {pca}, {physical}")),
            "{e}"
        );
    }

    #[cfg(unix)]
    #[test]
    fn a_model_or_hypotheses_file_that_is_no_regular_file_is_refused_unread() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("model.json");
        crate::make_fifo(&fifo);
        for path in [std::path::Path::new("/dev/zero"), fifo.as_path()] {
            let e = SavedModel::load(path).unwrap_err().to_string();
            assert_eq!(
                e,
                format!(
                    "{}: file: is not a regular file (a device, FIFO or folder)",
                    path.display()
                )
            );
            let e = crate::gap::user_effects::load(path)
                .unwrap_err()
                .to_string();
            assert!(e.contains("is not a regular file"), "{e}");
        }
    }
}
