//! Step 2's library of candidate effects: named physical mechanisms computed
//! from the energy maps and KPIs, each with a threshold grid that is scanned
//! inside the cross-validation (the thresholds are not known in advance),
//! plus every KPI the physics baseline does not use as a generic candidate.
//! Formulas and units: docs/gap.md.

use super::user_effects::UserEffect;
use crate::kpi::KpiRow;
use crate::kpi::cpu::condition_map::{CONDITIONS, Component, N_PAIRS, pair_conditions};
use crate::kpi::energy_maps::EnergyMaps;
use crate::kpi::table::ROAD_KPIS;
use crate::model::data::candidate_inputs;
use crate::{Axle, Wheel};
use std::sync::Arc;

/// How a candidate's term is computed for a row at threshold θ.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub enum Feature {
    /// Graining: lateral friction energy with a cold tread, i.e. the lateral
    /// map's energy in the bins whose tread-bulk temperature (mean of surface
    /// and inner liner) is below θ °C (MJ); for maps without the lateral map,
    /// the total map's energy there times the run's lateral share E_y/E.
    ColdTreadLateralEnergy,
    /// Blistering: friction energy with the inner liner above θ °C (MJ).
    HotInnerEnergy,
    /// Thermal degradation: friction energy with the surface above θ °C (MJ).
    HotSurfaceEnergy,
    /// Friction energy at sliding speeds above θ m/s (MJ).
    FastSlidingEnergy,
    /// Road abrasion: the law's energy term scaled by the road's
    /// micro-texture above θ, max(0, Ra_micro − θ)/(0.01 mm) (a rough road
    /// raises the abrasion per joule the law already counts; see
    /// [`candidate_feature`]).
    RoughRoadEnergy,
    /// Road abrasion growing with the square of the micro-texture above θ,
    /// (max(0, Ra_micro − θ)/(0.01 mm))²: hysteresis losses on a rough road
    /// grow with its mean-square slope, so the abrasion can rise faster
    /// than linearly, and a hinge would extrapolate it short.
    RoughRoadEnergySquared,
    /// Camber: friction energy scaled by the run's mean camber magnitude
    /// beyond θ, E·max(0, |γ_c| − θ) (MJ·°): a tilted contact patch
    /// concentrates the sliding on one shoulder.
    CamberEnergy,
    /// Pressure: friction energy scaled by the distance of the run's mean
    /// inflation pressure from θ, E·|p − θ|/(10 kPa) (MJ per 10 kPa): θ at
    /// the low end reads as over-inflation, at the high end as
    /// under-inflation, in between as an optimum.
    PressureEnergy,
    /// Contact patch: friction energy on a contact patch smaller than θ,
    /// E·max(0, θ − A)/(1000 mm²) (MJ per 1000 mm²): the same energy on a
    /// smaller patch means higher contact pressure.
    SmallPatchEnergy,
    /// Generic: friction energy × the KPI standardised over the rows scored,
    /// E·(x − mean)/sd (MJ): wear per joule that varies with the KPI. A road
    /// index is a track-level term on the law's energy instead
    /// ([`candidate_feature`]).
    Kpi(&'static str),
    /// Generated from the condition energy maps: the friction energy (the
    /// total, or its longitudinal or lateral part) of the samples whose
    /// condition `CONDITIONS[condition]` lies above θ (or below, `above`
    /// false), θ a bin edge (MJ). Wear per joule that is higher under some
    /// condition no named mechanism covers.
    ConditionEnergy {
        condition: usize,
        above: bool,
        component: Component,
    },
    /// Generated from the condition energy maps: the friction energy (total,
    /// longitudinal or lateral) of the samples whose condition
    /// `CONDITIONS[condition]` lies in a band [θ₁, θ₂), both ends bin edges
    /// of [`band_edges`] (MJ). θ is the index of the edge pair
    /// ([`band_thresholds`]): wear per joule that is higher in a window of
    /// the condition and not beyond it (a working range of the compound's
    /// temperature, say), which a single threshold extrapolates.
    BandEnergy {
        condition: usize,
        component: Component,
    },
    /// Generated from a pair map (`PAIRS[pair]`): the friction energy of
    /// the samples whose first condition lies above θ₁ (or below,
    /// `first_above` false) *and* whose second lies above θ₂ (or below),
    /// θ₁ and θ₂ inner edges of the conditions' coarse bins (MJ). θ is the
    /// index of the edge pair ([`pair_thresholds`]): a mechanism that needs
    /// two conditions at once.
    PairEnergy {
        pair: usize,
        first_above: bool,
        second_above: bool,
    },
    /// A user hypothesis from `effects.toml` (`Candidate::user`).
    User,
    /// Set-up: the law's own wear of the tires of one group (a car, a car's
    /// axle or wheel, a wheel position over every car; `Candidate::group`),
    /// or one component of their friction energy charged at the law's
    /// abrasion per joule ([`SetUpForm`], scanned as θ), zero elsewhere:
    /// wear per joule that differs for that group by a factor the telemetry
    /// does not explain (alignment, toe, a suspension setting, a tire
    /// batch). The coefficient c reads as "the group wears (1 + c) times the
    /// law" (or "its lateral energy abrades (1 + c) times the law's rate").
    Group,
}

/// What a set-up candidate's factor multiplies; its threshold θ is the
/// index into [`SetUpForm::ALL`] (NaN reads as the law's wear).
///
/// A toe or camber setting scales the energy of one direction of sliding
/// (lateral, say) rather than everything the law counts: on held-out
/// seasons such effects were taken by a band or an onset of some condition
/// that held 64–75 % of that energy on the right car (seeds 332 and 340,
/// docs/gap.md), because no candidate held it all. Scanned within the one
/// set-up candidate of a group, the forms do not add to the family of
/// tests: its max-F runs over them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum SetUpForm {
    /// The law's wear k·Σ E_b·φ(T_b)·exp(s·Sk) of the group's tires.
    LawWear,
    /// The group's friction energy of one component (MJ) times the law's
    /// abrasion per joule k·exp(s·Sk).
    Energy(Component),
}

impl SetUpForm {
    pub(crate) const ALL: [SetUpForm; 4] = [
        SetUpForm::LawWear,
        SetUpForm::Energy(Component::Total),
        SetUpForm::Energy(Component::Longitudinal),
        SetUpForm::Energy(Component::Lateral),
    ];

    /// The form threshold `theta` stands for.
    pub(crate) fn of(theta: f64) -> Option<SetUpForm> {
        if theta.is_nan() {
            return Some(SetUpForm::LawWear);
        }
        (theta >= 0.0 && theta.fract() == 0.0)
            .then(|| SetUpForm::ALL.get(theta as usize).copied())
            .flatten()
    }

    /// The thresholds a set-up candidate scans: every form.
    fn thresholds() -> Vec<f64> {
        (0..SetUpForm::ALL.len()).map(|i| i as f64).collect()
    }

    /// "the law's wear", "energy", "lateral energy".
    pub(crate) fn describe(self) -> &'static str {
        match self {
            SetUpForm::LawWear => "the law's wear",
            SetUpForm::Energy(c) => c.energy_name(),
        }
    }

    /// The row's term before the group's mask: the law's wear (%), or the
    /// component's energy charged at the law's abrasion per joule (%).
    fn term(self, r: &KpiRow, law: LawRow) -> f64 {
        let j = match self {
            SetUpForm::LawWear => return law.wear_pct,
            SetUpForm::Energy(Component::Total) => r.friction_energy_j,
            SetUpForm::Energy(Component::Longitudinal) => r.friction_energy_x_j,
            SetUpForm::Energy(Component::Lateral) => r.friction_energy_y_j,
        };
        law.abrasion * j * 1e-6
    }
}

impl Feature {
    /// The simulator's effect this mechanism stands for (`EffectKind::name`), if any.
    pub fn mechanism(&self) -> Option<&'static str> {
        match self {
            Feature::ColdTreadLateralEnergy => Some("graining"),
            Feature::HotInnerEnergy => Some("blistering"),
            Feature::HotSurfaceEnergy => Some("thermal"),
            Feature::RoughRoadEnergy | Feature::RoughRoadEnergySquared => Some("road-abrasion"),
            // Energy scaled by a road-texture index is road abrasion too:
            // with a season's handful of tracks, which index carries it
            // cannot be told apart (docs/gap.md).
            Feature::Kpi(c) if ROAD_KPIS.contains(c) => Some("road-abrasion"),
            // A pair with a named mechanism's point on one side (surface
            // above θ: thermal degradation; bulk below θ: graining) is that
            // mechanism, acting only where the other condition holds too.
            Feature::PairEnergy {
                pair,
                first_above,
                second_above,
            } => {
                let (a, b) = pair_conditions(*pair);
                NAMED_CONDITIONS.iter().find_map(|(name, above, f)| {
                    let side = (CONDITIONS[a].name == *name && first_above == above)
                        || (CONDITIONS[b].name == *name && second_above == above);
                    side.then(|| f.mechanism()).flatten()
                })
            }
            Feature::FastSlidingEnergy
            | Feature::CamberEnergy
            | Feature::PressureEnergy
            | Feature::SmallPatchEnergy
            | Feature::Kpi(_)
            | Feature::ConditionEnergy { .. }
            | Feature::BandEnergy { .. }
            | Feature::User
            | Feature::Group => None,
        }
    }

    /// A physical mechanism only adds wear: its coefficient must be positive.
    /// A generic KPI may act either way.
    pub(crate) fn adds_wear_only(&self) -> bool {
        !matches!(self, Feature::Kpi(_) | Feature::Group)
    }

    /// A term that is the row's law energy times a value of its track (road
    /// candidates): it can only be told apart from the other track-level
    /// causes by comparing tracks, so it is tested across tracks.
    pub(crate) fn track_level(&self) -> bool {
        match self {
            Feature::RoughRoadEnergy | Feature::RoughRoadEnergySquared => true,
            Feature::Kpi(c) => ROAD_KPIS.contains(c),
            _ => false,
        }
    }

    /// Energy under a per-sample condition (the named mechanisms, the
    /// condition and pair maps' terms): its between-track part is tested on
    /// the tracks' severities besides its within-track part
    /// (`Severities::p_between`). Not a generic KPI (a straight line in a
    /// run's average, which between tracks would stand in for any
    /// track-level cause), a set-up group or a user's hypothesis.
    pub(crate) fn tested_between_tracks(&self) -> bool {
        matches!(
            self,
            Feature::ColdTreadLateralEnergy
                | Feature::HotInnerEnergy
                | Feature::HotSurfaceEnergy
                | Feature::FastSlidingEnergy
                | Feature::ConditionEnergy { .. }
                | Feature::BandEnergy { .. }
                | Feature::PairEnergy { .. }
        )
    }

    /// Where a named mechanism acts, with θ for its threshold, for a name
    /// that does not hold θ itself ("graining (lateral energy with a cold
    /// tread)"): the Findings then say which threshold was fitted. `None`
    /// for the other features (their names hold θ, or they have none) and
    /// for a road term without a hinge (θ = 0).
    pub(crate) fn threshold_phrase(&self, theta: f64) -> Option<&'static str> {
        match self {
            Feature::ColdTreadLateralEnergy => Some("tread bulk below θ"),
            Feature::HotInnerEnergy => Some("inner liner above θ"),
            Feature::HotSurfaceEnergy => Some("surface above θ"),
            Feature::FastSlidingEnergy => Some("sliding faster than θ"),
            Feature::RoughRoadEnergy | Feature::RoughRoadEnergySquared if theta > 0.0 => {
                Some("micro-texture above θ")
            }
            _ => None,
        }
    }

    /// Unit of the threshold.
    pub(crate) fn threshold_unit(&self) -> &'static str {
        match self {
            Feature::ColdTreadLateralEnergy
            | Feature::HotInnerEnergy
            | Feature::HotSurfaceEnergy => "°C",
            Feature::FastSlidingEnergy => "m/s",
            Feature::RoughRoadEnergy | Feature::RoughRoadEnergySquared => "mm",
            Feature::CamberEnergy => "°",
            Feature::PressureEnergy => "Pa",
            Feature::SmallPatchEnergy => "mm²",
            Feature::ConditionEnergy { condition, .. } => match CONDITIONS[*condition].unit {
                "1" => "",
                u => u,
            },
            Feature::Kpi(_)
            | Feature::BandEnergy { .. }
            | Feature::PairEnergy { .. }
            | Feature::User
            | Feature::Group => "",
        }
    }
}

/// A value with a condition's unit, as thresholds print (pressure in kPa).
fn format_with_unit(unit: &str, x: f64) -> String {
    match unit {
        "Pa" => format!("{} kPa", significant(x / 1e3)),
        "" | "1" => significant(x),
        u => format!("{} {u}", significant(x)),
    }
}

/// The edges (θ₁, θ₂) a pair candidate's threshold index stands for: index
/// k = (i − 1)·(n₂ − 1) + (j − 1) for the inner edges i of the first
/// condition's coarse bins and j of the second's.
pub(crate) fn pair_thresholds(pair: usize, theta: f64) -> Option<(usize, usize)> {
    let (a, b) = pair_conditions(pair);
    let (na, nb) = (CONDITIONS[a].coarse.n, CONDITIONS[b].coarse.n);
    if theta.is_nan() || theta < 0.0 || theta.fract() != 0.0 {
        return None;
    }
    let k = theta as usize;
    (k < (na - 1) * (nb - 1)).then(|| (k / (nb - 1) + 1, k % (nb - 1) + 1))
}

/// How many edges a band candidate's ends are chosen from, at most
/// ([`band_edges`]): 9 edges give 36 bands, about as many columns as a
/// pair's 7 × 7 edge pairs.
const BAND_EDGES: usize = 9;

/// The fine bin edges (indices into the condition's bins) a band's ends
/// take: every ⌈n/10⌉-th inner edge of the condition's n bins.
pub(crate) fn band_edges(condition: usize) -> Vec<usize> {
    let (step, ends) = band_grid(condition);
    (1..=ends).map(|i| i * step).collect()
}

/// (step, number of ends) of [`band_edges`], without building the list:
/// [`band_thresholds`] runs for every row a band's term is computed on.
fn band_grid(condition: usize) -> (usize, usize) {
    let n = CONDITIONS[condition].bins.n;
    let step = n.div_ceil(BAND_EDGES + 1).max(1);
    (step, ((n - 1) / step).min(BAND_EDGES))
}

/// The edges (k₁, k₂), bin indices with k₁ < k₂, a band candidate's
/// threshold index stands for: the bands of [`band_edges`] in order (first
/// end, then second).
pub(crate) fn band_thresholds(condition: usize, theta: f64) -> Option<(usize, usize)> {
    if theta.is_nan() || theta < 0.0 || theta.fract() != 0.0 {
        return None;
    }
    let (step, ends) = band_grid(condition);
    let mut k = theta as usize;
    for i in 1..ends {
        let after = ends - i;
        if k < after {
            return Some((i * step, (i + 1 + k) * step));
        }
        k -= after;
    }
    None
}

/// The least share of a band candidate's energy component (over the rows
/// scored) that each side beyond the band must hold for the band to be
/// scanned ([`band_admissible`]).
pub(crate) const BAND_TAIL_SHARE: f64 = 0.05;

/// Whether band θ of `condition` leaves at least [`BAND_TAIL_SHARE`] of
/// `energy` (per bin, [`Candidate::band_energy`]) on each side of it.
///
/// A band whose low end lies below (nearly) all of the energy is, on these
/// tires, the one-sided threshold at its high end, and the data cannot
/// tell the two apart; they differ only where a testing track runs past
/// the end the training events never reached, and there the one-sided
/// form — the simpler assumption — keeps the effect going where the band
/// would cut it off. (Clean-noise seed 317, an onset of camber below
/// −1.9° on every tire: "energy with camber_deg between −5° and −2°",
/// 0.005 of CV gain ahead of "below −1.5°", left the testing events worse
/// than the baseline, −0.29 of the ideal against 0.66; docs/gap.md,
/// "Bands".)
pub(crate) fn band_admissible(energy: &[f64], condition: usize, theta: f64) -> bool {
    let total: f64 = energy.iter().sum();
    let least = BAND_TAIL_SHARE * total;
    band_thresholds(condition, theta).is_some_and(|(lo, hi)| {
        total > 0.0
            && energy[..lo].iter().sum::<f64>() >= least
            && energy[hi..].iter().sum::<f64>() >= least
    })
}

/// `x` with four significant digits (thresholds: 0.009022, 84.00, 1234).
pub fn significant(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let decimals = (3 - x.abs().log10().floor() as i32).max(0) as usize;
    format!("{x:.decimals$}")
}

impl Feature {
    /// θ with its unit, as the report prints it (pressure in kPa).
    pub(crate) fn format_threshold(&self, theta: f64) -> String {
        if let Feature::BandEnergy { condition, .. } = *self {
            let cd = &CONDITIONS[condition];
            return match band_thresholds(condition, theta) {
                Some((lo, hi)) => format!(
                    "{} and {}",
                    format_with_unit(cd.unit, cd.bins.lower_edge(lo)),
                    format_with_unit(cd.unit, cd.bins.lower_edge(hi))
                ),
                None => significant(theta),
            };
        }
        if *self == Feature::Group {
            return SetUpForm::of(theta)
                .map_or_else(|| significant(theta), |f| f.describe().into());
        }
        if let Feature::PairEnergy { pair, .. } = *self {
            let (a, b) = pair_conditions(pair);
            return match pair_thresholds(pair, theta) {
                Some((i, j)) => format!(
                    "({}, {})",
                    format_with_unit(CONDITIONS[a].unit, CONDITIONS[a].coarse.lower_edge(i)),
                    format_with_unit(CONDITIONS[b].unit, CONDITIONS[b].coarse.lower_edge(j))
                ),
                None => significant(theta),
            };
        }
        match self.threshold_unit() {
            "Pa" => format!("{} kPa", significant(theta / 1e3)),
            "" => significant(theta),
            u => format!("{} {u}", significant(theta)),
        }
    }
}

/// A named candidate with its threshold grid, acting on one axle or both.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Candidate {
    pub name: String,
    pub feature: Feature,
    pub thresholds: Vec<f64>,
    /// One axle, or None for both.
    pub axle: Option<Axle>,
    /// The compiled expression of a user hypothesis.
    #[serde(skip)]
    pub user: Option<Arc<UserEffect>>,
    /// The tires of a set-up candidate ([`Feature::Group`]), or of one
    /// scope of a condition candidate.
    pub group: Option<Group>,
    /// Scopes scanned as one candidate (a generated condition candidate):
    /// its statistic is the largest over thresholds *and* scopes, so the
    /// number of scopes does not multiply the family ([`Candidate::resolved`]).
    /// Empty: the candidate acts on `axle` and `group` alone.
    #[serde(skip)]
    pub scopes: Vec<Scope>,
}

/// One scope of a candidate scanned over several: its name suffix, axle
/// and group of tires.
#[derive(Debug, Clone, PartialEq)]
pub struct Scope {
    pub suffix: String,
    pub axle: Option<Axle>,
    pub group: Option<Group>,
}

/// A group of tires for a set-up candidate: every field that is set must
/// match (the candidate's `axle` restricts it further).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Group {
    pub car: Option<String>,
    pub wheel: Option<Wheel>,
}

impl Group {
    pub fn contains(&self, r: &KpiRow) -> bool {
        self.car.as_ref().is_none_or(|c| *c == r.car) && self.wheel.is_none_or(|w| w == r.wheel)
    }

    /// "car2", "car2, FL", "FL on every car".
    pub(crate) fn describe(&self) -> String {
        match (&self.car, &self.wheel) {
            (Some(c), Some(w)) => format!("{c}, {w}"),
            (Some(c), None) => c.clone(),
            (None, Some(w)) => format!("{w} on every car"),
            (None, None) => "every tire".into(),
        }
    }
}

impl Candidate {
    /// The candidates the scoring scans for this one: each of its scopes as
    /// a candidate of its own (named with the scope's suffix), or itself.
    pub(crate) fn resolved(&self) -> Vec<Candidate> {
        if self.scopes.is_empty() {
            return vec![self.clone()];
        }
        self.scopes
            .iter()
            .map(|s| Candidate {
                name: format!("{}{}", self.name, s.suffix),
                axle: s.axle,
                group: s.group.clone(),
                scopes: Vec::new(),
                ..self.clone()
            })
            .collect()
    }

    /// Its between-track part is tested in the first round: a per-sample
    /// mechanism's ([`Feature::tested_between_tracks`]), and a user
    /// hypothesis that adds wear, which sums per-sample energy as those do
    /// (so that one restating a built-in mechanism scores exactly like it).
    pub(crate) fn tested_between_tracks(&self) -> bool {
        self.feature.tested_between_tracks()
            || (self.feature == Feature::User && self.adds_wear_only())
    }

    /// Only positive coefficients count: built-in mechanisms, user
    /// hypotheses unless they say otherwise, and the set-up of a wheel
    /// position on every car. The law is calibrated per axle, so the other
    /// wheel of the axle is the same fit with the sign turned (equal CV gain
    /// and p): of the two readings the one that adds wear is kept, naming the
    /// tire that wears more, where the other said "wears −0.01 times the law".
    pub(crate) fn adds_wear_only(&self) -> bool {
        match (&self.user, &self.group) {
            (Some(u), _) => u.adds_wear,
            (None, Some(g)) if self.feature == Feature::Group => g.car.is_none(),
            (None, _) => self.feature.adds_wear_only(),
        }
    }

    /// The tires the term acts on, in words: "every tire", "the front
    /// axle", "car2", "car2's front axle", "the FL tire of every car",
    /// "car2's FL tire".
    pub(crate) fn scope_description(&self) -> String {
        let g = self.group.as_ref();
        match (
            g.and_then(|g| g.car.as_deref()),
            g.and_then(|g| g.wheel),
            self.axle,
        ) {
            (Some(c), Some(w), _) => format!("{c}'s {w} tire"),
            (Some(c), None, Some(a)) => format!("{c}'s {a} axle"),
            (Some(c), None, None) => c.to_string(),
            (None, Some(w), _) => format!("the {w} tire of every car"),
            (None, None, Some(a)) => format!("the {a} axle"),
            (None, None, None) => "every tire".into(),
        }
    }

    /// Whether the candidate's term acts on this row's tire: its axle and
    /// group (zero elsewhere, [`candidate_feature`]).
    pub(crate) fn acts_on(&self, r: &KpiRow) -> bool {
        self.axle.is_none_or(|a| r.axle == a) && self.group.as_ref().is_none_or(|g| g.contains(r))
    }

    /// A band candidate's energy component per bin of its condition,
    /// summed over the maps of the tires of `rows` it acts on; None for
    /// other candidates, or where no such tire has that condition's map.
    pub(crate) fn band_energy(
        &self,
        rows: &[&KpiRow],
        maps: &[Option<&EnergyMaps>],
    ) -> Option<Vec<f64>> {
        let Feature::BandEnergy {
            condition,
            component,
        } = self.feature
        else {
            return None;
        };
        let mut energy = vec![0.0; CONDITIONS[condition].bins.n];
        let mut any = false;
        for (r, m) in rows.iter().zip(maps) {
            let Some(cm) = m.and_then(|m| m.conditions.as_deref()) else {
                continue;
            };
            if self.acts_on(r) && cm.holds(condition) {
                let map = cm.map(component, condition);
                energy.iter_mut().zip(map).for_each(|(a, b)| *a += b);
                any = true;
            }
        }
        any.then_some(energy)
    }

    /// A condition or pair term's share of its energy component at
    /// threshold θ over `rows` (the tires it acts on): the energy its bins
    /// hold over all the energy of that component (its map's total). None
    /// for other kinds, or where no row has the maps. Near 1, no condition
    /// limits the term: it is a multiple of the whole component's wear on
    /// its tires, a set-up effect ([`SET_UP_SHARE`]).
    pub(crate) fn energy_share(
        &self,
        rows: &[&KpiRow],
        maps: &[Option<&EnergyMaps>],
        theta: f64,
    ) -> Option<f64> {
        let (mut held, mut all) = (0.0, 0.0);
        for (r, m) in rows.iter().zip(maps) {
            if !self.acts_on(r) {
                continue;
            }
            let Some(cm) = m.and_then(|m| m.conditions.as_deref()) else {
                continue;
            };
            let total: f64 = match self.feature {
                Feature::ConditionEnergy {
                    condition,
                    component,
                    ..
                } if cm.holds(condition) => cm.map(component, condition).iter().sum(),
                Feature::PairEnergy { pair, .. } if cm.pairs_held => cm.pair_map(pair).iter().sum(),
                Feature::BandEnergy {
                    condition,
                    component,
                } if cm.holds(condition) => cm.map(component, condition).iter().sum(),
                Feature::ConditionEnergy { .. }
                | Feature::BandEnergy { .. }
                | Feature::PairEnergy { .. } => continue,
                _ => return None,
            };
            let part = feature(self.feature, r, *m, theta, KpiScale::NONE) * 1e6;
            if part.is_finite() && total.is_finite() {
                held += part;
                all += total;
            }
        }
        (all > 0.0).then(|| held / all)
    }
}

impl Feature {
    /// The energy a condition or pair term bins, as the report names it
    /// ("energy", "longitudinal energy", "lateral energy"); None for other
    /// kinds.
    pub(crate) fn energy_component(&self) -> Option<&'static str> {
        match *self {
            Feature::ConditionEnergy { component, .. } | Feature::BandEnergy { component, .. } => {
                Some(component.energy_name())
            }
            Feature::PairEnergy { .. } => Some("energy"),
            _ => None,
        }
    }
}

/// The energy share ([`Candidate::energy_share`]) from which a condition
/// or pair term is reported as acting under (nearly) every condition — on
/// a car, a car's axle or a wheel position, a set-up effect: its threshold
/// leaves out at most 5 % of the energy of its component on its tires, so what it
/// says is that those tires wear more per joule under (nearly) every
/// condition. (A set-up factor planted on car2's front axle was taken as
/// "energy with accel_x_mps2 above −39 m/s²", 96 % of that energy, among a
/// dozen such terms whose held-out gains differ in the third decimal.)
pub const SET_UP_SHARE: f64 = 0.95;

/// KPI columns the physics baseline already uses, and the one the road
/// abrasion mechanism scales by: not generic candidates.
pub(crate) const BASELINE_KPIS: [&str; 4] = [
    "friction_energy_j",
    "t_surface_avg_c",
    "skewness",
    "ra_micro_mm",
];

/// The library: six wear mechanisms (road abrasion in two forms), each on
/// both axles and on each axle alone; three set-up mechanisms (camber,
/// pressure, contact patch) on both axles; every KPI the physics baseline
/// does not use (road-texture indexes as road abrasion).
pub fn library(rows: &[&KpiRow]) -> Vec<Candidate> {
    let steps = |lo: f64, hi: f64, step: f64| -> Vec<f64> {
        (0..)
            .map(|i| lo + step * i as f64)
            .take_while(|v| *v <= hi + 1e-9)
            .collect()
    };
    // Road abrasion: no threshold, or each track's micro-texture value that
    // leaves at least three tracks above it (a hinge that singles out one or
    // two tracks would fit any track-level noise: the test pays for it).
    let mut micro: Vec<f64> = rows
        .iter()
        .map(|r| r.ra_micro_mm)
        .filter(|v| v.is_finite())
        .collect();
    micro.sort_by(f64::total_cmp);
    micro.dedup();
    micro.truncate(micro.len().saturating_sub(3));
    micro.insert(0, 0.0);
    let mechanisms: Vec<(&str, Feature, Vec<f64>)> = vec![
        (
            "graining (lateral energy with a cold tread)",
            Feature::ColdTreadLateralEnergy,
            steps(60.0, 110.0, 5.0),
        ),
        (
            "blistering (energy with a hot inner liner)",
            Feature::HotInnerEnergy,
            steps(90.0, 140.0, 5.0),
        ),
        (
            "thermal degradation (energy with a hot surface)",
            Feature::HotSurfaceEnergy,
            steps(70.0, 120.0, 5.0),
        ),
        (
            "fast sliding (energy at high sliding speed)",
            Feature::FastSlidingEnergy,
            steps(0.5, 5.0, 0.5),
        ),
        (
            "road abrasion (energy on micro-rough roads)",
            Feature::RoughRoadEnergy,
            micro.clone(),
        ),
        (
            "road abrasion (energy × squared micro-roughness)",
            Feature::RoughRoadEnergySquared,
            micro,
        ),
    ];
    let mut out = Vec::new();
    for (name, feature, thresholds) in mechanisms {
        for axle in [None, Some(Axle::Front), Some(Axle::Rear)] {
            out.push(Candidate {
                name: match axle {
                    None => name.to_string(),
                    Some(a) => format!("{name}, {a} axle"),
                },
                feature,
                thresholds: thresholds.clone(),
                axle,
                user: None,
                group: None,
                scopes: Vec::new(),
            });
        }
    }
    out.extend(condition_candidates(&setup_cars(rows)));
    out.extend(band_candidates(&setup_cars(rows)));
    out.extend(pair_candidates(&setup_cars(rows)));
    // Set-up mechanisms, on both axles (the generic KPI candidates below
    // cover them linearly too); thresholds at the deciles of the rows.
    let deciles = |col: &str, f: fn(f64) -> f64| -> Vec<f64> {
        let mut v: Vec<f64> = rows
            .iter()
            .filter_map(|r| r.number(col))
            .map(f)
            .filter(|x| x.is_finite())
            .collect();
        v.sort_by(f64::total_cmp);
        let mut q: Vec<f64> = (0..=10)
            .filter_map(|d| v.get((d * v.len().saturating_sub(1)) / 10).copied())
            .collect();
        q.dedup();
        q
    };
    let mut camber = deciles("camber_avg_deg", f64::abs);
    camber.pop();
    camber.insert(0, 0.0);
    let mut patch = deciles("contact_patch_mm2", |x| x);
    // The smallest patch is no threshold (nothing lies below it); a column
    // with no finite value gives no thresholds and no candidate.
    if !patch.is_empty() {
        patch.remove(0);
    }
    let setup: [(&str, Feature, Vec<f64>); 3] = [
        (
            "camber (energy × camber beyond θ)",
            Feature::CamberEnergy,
            camber,
        ),
        (
            "pressure (energy × distance of the pressure from θ)",
            Feature::PressureEnergy,
            deciles("pressure_avg_pa", |x| x),
        ),
        (
            "contact patch (energy on a patch smaller than θ)",
            Feature::SmallPatchEnergy,
            patch,
        ),
    ];
    for (name, feature, thresholds) in setup {
        if !thresholds.is_empty() {
            out.push(Candidate {
                name: name.to_string(),
                feature,
                thresholds,
                axle: None,
                user: None,
                group: None,
                scopes: Vec::new(),
            });
        }
    }
    out.extend(setup_candidates(rows));
    for c in candidate_inputs() {
        if !BASELINE_KPIS.contains(&c) {
            out.push(Candidate {
                name: if ROAD_KPIS.contains(&c) {
                    format!("road abrasion (energy × road index {c})")
                } else {
                    format!("KPI {c}")
                },
                feature: Feature::Kpi(c),
                thresholds: vec![f64::NAN],
                axle: None,
                user: None,
                group: None,
                scopes: Vec::new(),
            });
        }
    }
    out
}

/// Named mechanisms that are points of the generated space: (condition,
/// above) → the mechanism's candidate, which stands for it on every energy
/// component (one registry line per mechanism). The generated space leaves
/// those points out: a near copy of a mechanism (its lateral part, say)
/// would otherwise enter as a second term beside it and fit its noise.
pub(crate) const NAMED_CONDITIONS: [(&str, bool, Feature); 4] = [
    ("t_surface_c", true, Feature::HotSurfaceEnergy),
    ("t_inner_c", true, Feature::HotInnerEnergy),
    ("sliding_speed_mps", true, Feature::FastSlidingEnergy),
    ("t_bulk_c", false, Feature::ColdTreadLateralEnergy),
];

/// Candidates generated from the condition energy maps: for every condition
/// and energy component (total, longitudinal, lateral), the energy above θ
/// and below θ (θ every other inner bin edge, scanned in the
/// cross-validation like a mechanism's threshold), on both axles, on each
/// alone and on each wheel position ([`condition_scopes`]) — except the points a named mechanism already covers
/// ([`NAMED_CONDITIONS`], on every component). Rows whose extraction wrote no
/// condition maps, or maps without that condition, give NaN terms, and the
/// scoring passes these candidates over.
fn condition_candidates(cars: &[String]) -> Vec<Candidate> {
    let mut out = Vec::new();
    for (c, cd) in CONDITIONS.iter().enumerate() {
        let thresholds: Vec<f64> = (2..cd.bins.n)
            .step_by(2)
            .map(|k| cd.bins.lower_edge(k))
            .collect();
        for component in Component::ALL {
            for above in [true, false] {
                if NAMED_CONDITIONS
                    .iter()
                    .any(|(name, a, _)| *name == cd.name && *a == above)
                {
                    continue;
                }
                let side = if above { "above" } else { "below" };
                out.push(Candidate {
                    name: format!("{} with {} {side} θ", component.energy_name(), cd.name),
                    feature: Feature::ConditionEnergy {
                        condition: c,
                        above,
                        component,
                    },
                    thresholds: thresholds.clone(),
                    axle: None,
                    user: None,
                    group: None,
                    scopes: condition_scopes(cars),
                });
            }
        }
    }
    out
}

/// Candidates generated from the condition energy maps' bands: for every
/// condition and energy component, the energy with the condition between
/// θ₁ and θ₂ (every band between two of [`band_edges`], scanned as one
/// threshold), on the condition candidates' scopes. A window's effect
/// taken by a one-sided threshold reaches beyond the window on tracks
/// where the condition runs past it (docs/gap.md, "Bands").
fn band_candidates(cars: &[String]) -> Vec<Candidate> {
    let mut out = Vec::new();
    for (c, cd) in CONDITIONS.iter().enumerate() {
        let edges = band_edges(c).len();
        let bands = edges * edges.saturating_sub(1) / 2;
        for component in Component::ALL {
            out.push(Candidate {
                name: format!("{} with {} between θ", component.energy_name(), cd.name),
                feature: Feature::BandEnergy {
                    condition: c,
                    component,
                },
                thresholds: (0..bands).map(|k| k as f64).collect(),
                axle: None,
                user: None,
                group: None,
                scopes: condition_scopes(cars),
            });
        }
    }
    out
}

/// Candidates generated from the pair maps: for every pair of
/// `condition_map::PAIRS` and quadrant (each condition above or below its
/// threshold), the energy where both hold, θ₁ and θ₂ every inner edge of
/// the coarse bins (7 × 7 edge pairs, scanned as one threshold), on the
/// condition candidates' scopes. Rows without pair maps (an older
/// extraction) give NaN terms.
fn pair_candidates(cars: &[String]) -> Vec<Candidate> {
    let side = |above: bool| if above { "above" } else { "below" };
    let mut out = Vec::new();
    for pair in 0..N_PAIRS {
        let (a, b) = pair_conditions(pair);
        let edges = (CONDITIONS[a].coarse.n - 1) * (CONDITIONS[b].coarse.n - 1);
        for (first_above, second_above) in
            [(true, true), (true, false), (false, true), (false, false)]
        {
            out.push(Candidate {
                name: format!(
                    "energy with ({}, {}) {}/{} θ",
                    CONDITIONS[a].name,
                    CONDITIONS[b].name,
                    side(first_above),
                    side(second_above)
                ),
                feature: Feature::PairEnergy {
                    pair,
                    first_above,
                    second_above,
                },
                thresholds: (0..edges).map(|k| k as f64).collect(),
                axle: None,
                user: None,
                group: None,
                scopes: condition_scopes(cars),
            });
        }
    }
    out
}

/// The scopes of a generated condition candidate: both axles, each axle,
/// each wheel position on every car (a mechanism one corner's set-up or
/// load case brings out), and each of `cars` and its axles (a mechanism one
/// car's set-up brings out: without these, a condition acting on one car
/// was taken by that car's set-up factor, a constant multiple, at 0.51–0.71
/// of the ideal; docs/gap.md).
fn condition_scopes(cars: &[String]) -> Vec<Scope> {
    let scope = |suffix: String, axle, group| Scope {
        suffix,
        axle,
        group,
    };
    let mut out = vec![
        scope(String::new(), None, None),
        scope(", front axle".into(), Some(Axle::Front), None),
        scope(", rear axle".into(), Some(Axle::Rear), None),
    ];
    for w in Wheel::ALL {
        let group = Group {
            car: None,
            wheel: Some(w),
        };
        out.push(scope(format!(", {w} wheel"), Some(w.axle()), Some(group)));
    }
    for car in cars {
        let group = Group {
            car: Some(car.clone()),
            wheel: None,
        };
        out.push(scope(format!(", {car}"), None, Some(group.clone())));
        for a in Axle::ALL {
            out.push(scope(
                format!(", {car}, {a} axle"),
                Some(a),
                Some(group.clone()),
            ));
        }
    }
    out
}

/// The cars a car-scoped candidate may stand for: those seen at
/// [`SETUP_MIN_EVENTS`] events or more, when there is more than one car
/// (one car's scope is every tire).
fn setup_cars(rows: &[&KpiRow]) -> Vec<String> {
    let mut cars: Vec<&str> = rows.iter().map(|r| r.car.as_str()).collect();
    cars.sort();
    cars.dedup();
    if cars.len() < 2 {
        return Vec::new();
    }
    cars.into_iter()
        .filter(|car| {
            let mut events: Vec<&str> = rows
                .iter()
                .filter(|r| r.car == *car)
                .map(|r| r.event.as_str())
                .collect();
            events.sort();
            events.dedup();
            events.len() >= SETUP_MIN_EVENTS
        })
        .map(str::to_string)
        .collect()
}

/// Events a set-up group must appear at: its factor is then tested on whole
/// tracks or events left out, not on the days of one.
pub(crate) const SETUP_MIN_EVENTS: usize = 3;

/// Set-up candidates: each car, each car's axle and wheel, each wheel
/// position over every car — those seen at [`SETUP_MIN_EVENTS`] events or
/// more that are not every tire their axle scope holds (that is the law's
/// own compound-and-axle k).
fn setup_candidates(rows: &[&KpiRow]) -> Vec<Candidate> {
    let mut cars: Vec<&str> = rows.iter().map(|r| r.car.as_str()).collect();
    cars.sort();
    cars.dedup();
    let mut groups: Vec<(Group, Option<Axle>)> = Vec::new();
    for car in &cars {
        let car = Some(car.to_string());
        for axle in [None, Some(Axle::Front), Some(Axle::Rear)] {
            groups.push((
                Group {
                    car: car.clone(),
                    wheel: None,
                },
                axle,
            ));
        }
        for w in Wheel::ALL {
            groups.push((
                Group {
                    car: car.clone(),
                    wheel: Some(w),
                },
                None,
            ));
        }
    }
    for w in Wheel::ALL {
        groups.push((
            Group {
                car: None,
                wheel: Some(w),
            },
            None,
        ));
    }
    groups
        .into_iter()
        .filter(|(g, axle)| {
            let in_scope = |r: &&&KpiRow| axle.is_none_or(|a| r.axle == a);
            let members: Vec<&&KpiRow> = rows
                .iter()
                .filter(in_scope)
                .filter(|r| g.contains(r))
                .collect();
            let mut events: Vec<&str> = members.iter().map(|r| r.event.as_str()).collect();
            events.sort();
            events.dedup();
            events.len() >= SETUP_MIN_EVENTS && members.len() < rows.iter().filter(in_scope).count()
        })
        .map(|(g, axle)| Candidate {
            name: match axle {
                None => format!("set-up: {}", g.describe()),
                Some(a) => format!("set-up: {}, {a} axle", g.describe()),
            },
            feature: Feature::Group,
            thresholds: SetUpForm::thresholds(),
            axle,
            user: None,
            group: Some(g),
            scopes: Vec::new(),
        })
        .collect()
}

/// Micro-texture above θ, in units of 0.01 mm.
fn road_excess(ra_micro_mm: f64, theta: f64) -> f64 {
    (ra_micro_mm - theta).max(0.0) / 0.01
}

/// The energy of one row's term at threshold θ (MJ), before
/// [`candidate_feature`] charges it; `kpi_scale` standardises a generic
/// KPI over the rows scored. NaN for the road-abrasion forms, which only
/// exist as track-level terms.
pub(crate) fn feature(
    f: Feature,
    r: &KpiRow,
    maps: Option<&EnergyMaps>,
    theta: f64,
    kpi_scale: KpiScale,
) -> f64 {
    let mj = 1e-6;
    let sum_surface_inner = |keep: &dyn Fn(f64, f64) -> bool| -> f64 {
        maps.map_or(f64::NAN, |m| {
            m.weighted_surface_inner(|ts, ti| keep(ts, ti) as u8 as f64) * mj
        })
    };
    match f {
        Feature::ColdTreadLateralEnergy => match maps {
            // The lateral map bins each sample's lateral energy by its own
            // temperatures.
            Some(m) if m.has_lateral() => {
                m.weighted_lateral_surface_inner(|ts, ti| (0.5 * (ts + ti) < theta) as u8 as f64)
                    * mj
            }
            // Maps written before the lateral map: the run's lateral share
            // of the energy with a cold tread.
            _ => {
                let lateral_share = if r.friction_energy_j > 0.0 {
                    r.friction_energy_y_j / r.friction_energy_j
                } else {
                    0.0
                };
                lateral_share * sum_surface_inner(&|ts, ti| 0.5 * (ts + ti) < theta)
            }
        },
        Feature::HotInnerEnergy => sum_surface_inner(&|_, ti| ti > theta),
        Feature::HotSurfaceEnergy => sum_surface_inner(&|ts, _| ts > theta),
        Feature::FastSlidingEnergy => maps.map_or(f64::NAN, |m| {
            m.weighted_speed_surface(|v, _| (v > theta) as u8 as f64) * mj
        }),
        // Track-level: `candidate_feature` scales the law's energy.
        Feature::RoughRoadEnergy | Feature::RoughRoadEnergySquared => f64::NAN,
        Feature::CamberEnergy => {
            r.friction_energy_j * mj * (r.camber_avg_deg.abs() - theta).max(0.0)
        }
        Feature::PressureEnergy => {
            r.friction_energy_j * mj * (r.pressure_avg_pa - theta).abs() / 1e4
        }
        Feature::SmallPatchEnergy => {
            r.friction_energy_j * mj * (theta - r.contact_patch_mm2).max(0.0) / 1e3
        }
        Feature::Kpi(c) => {
            r.friction_energy_j * mj * kpi_scale.standardised(r.number(c).unwrap_or(f64::NAN))
        }
        Feature::ConditionEnergy {
            condition,
            above,
            component,
        } => maps
            .and_then(|m| m.conditions.as_deref())
            .filter(|cm| cm.holds(condition))
            .map_or(f64::NAN, |cm| {
                let bins = CONDITIONS[condition].bins;
                let tol = 1e-9 * (1.0 + theta.abs());
                let map = cm.map(component, condition);
                // The bins kept are a suffix (above θ) or a prefix (below)
                // of the map, the edges rising with the bin: its end by
                // bisection, then the same sum in the same order as over
                // the bins that pass, without testing each (this ran for
                // every row, threshold and scope of every candidate).
                let below = |b: usize| bins.lower_edge(b + 1) <= theta + tol;
                let kept = if above {
                    &map[first_bin(map.len(), |b| bins.lower_edge(b) >= theta - tol)..]
                } else {
                    &map[..first_bin(map.len(), |b| !below(b))]
                };
                kept.iter().sum::<f64>() * mj
            }),
        Feature::BandEnergy {
            condition,
            component,
        } => maps
            .and_then(|m| m.conditions.as_deref())
            .filter(|cm| cm.holds(condition))
            .zip(band_thresholds(condition, theta))
            .map_or(f64::NAN, |(cm, (lo, hi))| {
                cm.map(component, condition)[lo..hi].iter().sum::<f64>() * mj
            }),
        Feature::PairEnergy {
            pair,
            first_above,
            second_above,
        } => maps
            .and_then(|m| m.conditions.as_deref())
            .filter(|cm| cm.pairs_held)
            .zip(pair_thresholds(pair, theta))
            .map_or(f64::NAN, |(cm, (i0, j0))| {
                let (_, b) = pair_conditions(pair);
                let nb = CONDITIONS[b].coarse.n;
                let map = cm.pair_map(pair);
                // The cells kept are a rectangle of the row-major map: its
                // rows in turn, in the order of a pass over every cell.
                let span = |edge: usize, above: bool, n: usize| {
                    if above { edge..n } else { 0..edge.min(n) }
                };
                let columns = span(j0, second_above, nb);
                span(i0, first_above, map.len() / nb)
                    .flat_map(|i| &map[i * nb + columns.start..i * nb + columns.end])
                    .sum::<f64>()
                    * mj
            }),
        // Needs the candidate's expression or group: see `candidate_feature`.
        Feature::User | Feature::Group => f64::NAN,
    }
}

/// The first of bins 0..n where `pass` holds, n when none does; `pass`
/// must fail on a prefix and hold on the rest (bisection).
fn first_bin(n: usize, pass: impl Fn(usize) -> bool) -> usize {
    let (mut lo, mut hi) = (0, n);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if pass(mid) {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    lo
}

/// What the baseline's law says about one row; the mechanisms' terms are
/// expressed in it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LawRow {
    /// The law's abrasion per joule of this tire at the reference
    /// temperature, k_{c,a}·exp(s·Sk) (% per MJ) under the physics baseline;
    /// 1 under a statistical one.
    pub abrasion: f64,
    /// The law's energy term Σ_b E_b·φ(T_b)·exp(s·Sk) (MJ): its wear
    /// without the compound-and-axle k; the friction energy under a
    /// statistical baseline.
    pub energy_mj: f64,
    /// The law's wear k_{c,a}·energy term (%); the friction energy (MJ)
    /// under a statistical baseline. A set-up term is this, in its group.
    pub wear_pct: f64,
}

impl LawRow {
    /// A statistical baseline's row: no law, the raw friction energy.
    pub fn raw(r: &KpiRow) -> LawRow {
        LawRow {
            abrasion: 1.0,
            energy_mj: r.friction_energy_j * 1e-6,
            wear_pct: r.friction_energy_j * 1e-6,
        }
    }
}

/// A candidate's term for a row: zero on the other axle, and outside its
/// group (a set-up group, or the wheel position of a condition candidate).
///
/// Under the physics baseline a built-in mechanism's energy is charged at
/// the law's own abrasion per joule for that tire (its compound, axle and
/// road): a wear mechanism abrades the same rubber on the same road, so its
/// coefficient is how many times the law's abrasion per joule it adds. A
/// road (track-level) term is the law's energy term times its track's
/// value: a rough road raises the abrasion the law counts, so the term is a
/// fixed share of the law's wear at each track (up to k), which is what the
/// tracks' severities test. Not times k: the fronts' k also carries their
/// irregular wear, which the road does not scale (docs/gap.md). A set-up
/// term is the law's whole wear in its group (a factor on the law), or
/// one component of its energy charged like a mechanism ([`SetUpForm`]). A user
/// hypothesis that adds wear is charged like a built-in mechanism; generic
/// KPI terms and two-sided hypotheses stay on the raw friction energy.
pub(crate) fn candidate_feature(
    c: &Candidate,
    r: &KpiRow,
    maps: Option<&EnergyMaps>,
    theta: f64,
    kpi_scale: KpiScale,
    law: LawRow,
) -> f64 {
    match (c.axle, &c.user) {
        (Some(a), _) if r.axle != a => 0.0,
        _ if c.group.as_ref().is_some_and(|g| !g.contains(r)) => 0.0,
        _ if c.feature == Feature::Group => match (&c.group, SetUpForm::of(theta)) {
            (Some(_), Some(form)) => form.term(r, law),
            _ => 0.0,
        },
        (_, Some(u)) if u.adds_wear => law.abrasion * u.feature(r, maps, theta),
        (_, Some(u)) => u.feature(r, maps, theta),
        _ if c.feature.track_level() => row_factor(c, r, law) * track_value(c, r, theta, kpi_scale),
        _ if c.feature.adds_wear_only() => {
            law.abrasion * feature(c.feature, r, maps, theta, kpi_scale)
        }
        _ => feature(c.feature, r, maps, theta, kpi_scale),
    }
}

/// How a generic KPI enters its term: standardised over the rows scored,
/// and held within the range seen there. A generic term is a straight line
/// in the KPI with no physics behind it, so it is not extended beyond the
/// training data, and new events can lie far outside it (on a season-preset
/// season the two coldest tracks, both testing events, have 1.6 times the
/// longest training track's sliding distance).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KpiScale {
    pub mean: f64,
    pub sd: f64,
    /// The range of the rows scored.
    pub min: f64,
    pub max: f64,
}

impl KpiScale {
    /// No standardising: for every candidate but a generic KPI.
    pub const NONE: KpiScale = KpiScale {
        mean: 0.0,
        sd: 1.0,
        min: f64::NEG_INFINITY,
        max: f64::INFINITY,
    };

    /// (clamp(x, min, max) − mean)/sd; 0 for a constant column.
    pub(crate) fn standardised(&self, x: f64) -> f64 {
        if self.sd > 0.0 {
            (x.clamp(self.min, self.max) - self.mean) / self.sd
        } else {
            0.0
        }
    }
}

/// The [`KpiScale`] of a generic KPI candidate's column over `rows`;
/// [`KpiScale::NONE`] otherwise.
pub(crate) fn kpi_scale(c: &Candidate, rows: &[&KpiRow]) -> KpiScale {
    let Feature::Kpi(col) = c.feature else {
        return KpiScale::NONE;
    };
    let v: Vec<f64> = rows.iter().filter_map(|r| r.number(col)).collect();
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    KpiScale {
        mean,
        sd: if sd.is_finite() { sd } else { 0.0 },
        min: v.iter().copied().fold(f64::INFINITY, f64::min),
        max: v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    }
}

/// A track-level term factored as `row_factor · track_value`: the law's
/// energy term of the row (zero off the candidate's axle) and its track's
/// value at θ.
pub(crate) fn row_factor(c: &Candidate, r: &KpiRow, law: LawRow) -> f64 {
    match c.axle {
        Some(a) if r.axle != a => 0.0,
        _ => law.energy_mj,
    }
}

/// The track's value of a track-level candidate at θ (see [`row_factor`]).
pub(crate) fn track_value(
    c: &Candidate,
    track_row: &KpiRow,
    theta: f64,
    kpi_scale: KpiScale,
) -> f64 {
    match c.feature {
        Feature::RoughRoadEnergy => road_excess(track_row.ra_micro_mm, theta),
        Feature::RoughRoadEnergySquared => road_excess(track_row.ra_micro_mm, theta).powi(2),
        Feature::Kpi(col) => kpi_scale.standardised(track_row.number(col).unwrap_or(f64::NAN)),
        _ => f64::NAN,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A KPI table whose set-up columns hold no finite value (a damaged or
    /// foreign table) gives no set-up candidates on them and no panic (the
    /// contact patch's grid dropped its first decile of an empty list).
    #[test]
    fn set_up_columns_without_a_finite_value_give_no_candidate() {
        let rows: Vec<KpiRow> = (0..8)
            .map(|k| KpiRow {
                contact_patch_mm2: f64::NAN,
                camber_avg_deg: f64::INFINITY,
                pressure_avg_pa: 1.8e5 + 1e3 * k as f64,
                ..Default::default()
            })
            .collect();
        let refs: Vec<&KpiRow> = rows.iter().collect();
        let lib = library(&refs);
        let has = |f: Feature| lib.iter().any(|c| c.feature == f);
        assert!(!has(Feature::SmallPatchEnergy));
        assert!(has(Feature::PressureEnergy));
        // Camber's grid starts at 0 whatever the column holds.
        let camber = lib.iter().find(|c| c.feature == Feature::CamberEnergy);
        assert_eq!(camber.map(|c| c.thresholds.clone()), Some(vec![0.0]));
    }

    #[test]
    fn condition_and_pair_sums_are_the_bin_by_bin_filters_bits() {
        // Every condition (above and below, thresholds on, between, beside
        // and beyond the edges, NaN) and every pair threshold, on random
        // maps: bit for bit the sum over every bin that passes the test
        // written bin by bin here.
        use crate::kpi::cpu::condition_map::{Component, ConditionMaps, N_PAIRS, pair_conditions};
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let mut cm = ConditionMaps::default();
        for v in cm
            .energy_j
            .iter_mut()
            .flatten()
            .chain(cm.pairs_j.iter_mut())
        {
            *v = if rng.random_bool(0.2) {
                0.0
            } else {
                rng.random_range(0.0..1e6)
            };
        }
        let mut m = EnergyMaps::new();
        m.conditions = Some(Box::new(cm.clone()));
        let r = KpiRow::default();
        for (condition, c) in CONDITIONS.iter().enumerate() {
            let bins = c.bins;
            let mut thetas = vec![f64::NAN, bins.lo - 1.0, bins.lower_edge(bins.n) + 1.0];
            for b in 0..=bins.n {
                let e = bins.lower_edge(b);
                thetas.extend([e, e + 0.3 * bins.width, e - 1e-12, e + 1e-12]);
            }
            for component in Component::ALL {
                for above in [true, false] {
                    for &theta in &thetas {
                        let f = Feature::ConditionEnergy {
                            condition,
                            above,
                            component,
                        };
                        let got = feature(f, &r, Some(&m), theta, KpiScale::NONE);
                        let tol = 1e-9 * (1.0 + theta.abs());
                        let want = cm
                            .map(component, condition)
                            .iter()
                            .enumerate()
                            .filter(|(b, _)| {
                                if above {
                                    bins.lower_edge(*b) >= theta - tol
                                } else {
                                    bins.lower_edge(b + 1) <= theta + tol
                                }
                            })
                            .map(|(_, e)| e)
                            .sum::<f64>()
                            * 1e-6;
                        assert_eq!(got.to_bits(), want.to_bits(), "{} {above} {theta}", c.name);
                    }
                }
            }
        }
        for pair in 0..N_PAIRS {
            let nb = CONDITIONS[pair_conditions(pair).1].coarse.n;
            for first_above in [true, false] {
                for second_above in [true, false] {
                    for k in 0..60 {
                        let theta = k as f64;
                        let f = Feature::PairEnergy {
                            pair,
                            first_above,
                            second_above,
                        };
                        let got = feature(f, &r, Some(&m), theta, KpiScale::NONE);
                        let want = match pair_thresholds(pair, theta) {
                            None => f64::NAN,
                            Some((i0, j0)) => {
                                let keep =
                                    |k: usize, edge: usize, above: bool| (k >= edge) == above;
                                cm.pair_map(pair)
                                    .iter()
                                    .enumerate()
                                    .filter(|(cell, _)| {
                                        keep(cell / nb, i0, first_above)
                                            && keep(cell % nb, j0, second_above)
                                    })
                                    .map(|(_, e)| e)
                                    .sum::<f64>()
                                    * 1e-6
                            }
                        };
                        assert_eq!(got.to_bits(), want.to_bits(), "pair {pair}, θ {theta}");
                    }
                }
            }
        }
    }

    /// Speed map (total energy), 1 m/s bins from 0: car1's FL tire 3 MJ at
    /// 2–3 m/s and 1 MJ at 10–11 m/s, car2's FL tire 5 MJ at 10–11 m/s;
    /// above 5 m/s car1 holds 1 of its 4 MJ, both together 6 of 9.
    #[test]
    fn energy_share_by_hand() {
        use crate::kpi::cpu::condition_map::{Component, ConditionMaps};
        let speed = ConditionMaps::condition_index("speed_mps").unwrap();
        let bins = CONDITIONS[speed].bins;
        let offset: usize = CONDITIONS[..speed].iter().map(|c| c.bins.n).sum();
        let bin = |v: f64| offset + bins.index(v);
        let maps = |cells: &[(f64, f64)]| {
            let mut cm = ConditionMaps::default();
            for &(v, e) in cells {
                cm.energy_j[Component::Total as usize][bin(v)] += e;
            }
            let mut m = EnergyMaps::new();
            m.conditions = Some(Box::new(cm));
            m
        };
        let row = |car: &str| KpiRow {
            car: car.into(),
            wheel: Wheel::FL,
            axle: Axle::Front,
            ..Default::default()
        };
        let (r1, r2) = (row("car1"), row("car2"));
        let (m1, m2) = (maps(&[(2.5, 3e6), (10.5, 1e6)]), maps(&[(10.5, 5e6)]));
        let rows = [&r1, &r2];
        let row_maps = [Some(&m1), Some(&m2)];
        let theta = bins.lower_edge(bins.index(5.5));
        let mut c = Candidate {
            name: "energy with speed_mps above θ".into(),
            feature: Feature::ConditionEnergy {
                condition: speed,
                above: true,
                component: Component::Total,
            },
            thresholds: vec![theta],
            axle: None,
            user: None,
            group: None,
            scopes: Vec::new(),
        };
        let share =
            |c: &Candidate, maps: &[Option<&EnergyMaps>]| c.energy_share(&rows, maps, theta);
        assert!((share(&c, &row_maps).unwrap() - 6.0 / 9.0).abs() < 1e-12);
        // On car1 alone; a row without maps counts for nothing.
        c.group = Some(Group {
            car: Some("car1".into()),
            wheel: None,
        });
        assert!((share(&c, &row_maps).unwrap() - 0.25).abs() < 1e-12);
        assert!((share(&c, &[Some(&m1), None]).unwrap() - 0.25).abs() < 1e-12);
        assert_eq!(share(&c, &[None, None]), None);
        // On the rear axle: no tire, no share; not a condition, none either.
        c.group = None;
        c.axle = Some(Axle::Rear);
        assert_eq!(share(&c, &row_maps), None);
        c.axle = None;
        c.feature = Feature::HotSurfaceEnergy;
        assert_eq!(share(&c, &row_maps), None);
    }

    /// A front tire's law in the tests below: it abrades 0.4 %/MJ over an
    /// energy term of 2.5 MJ, 1.3 % of wear.
    const FRONT_LAW: LawRow = LawRow {
        abrasion: 0.4,
        energy_mj: 2.5,
        wear_pct: 1.3,
    };

    #[test]
    fn a_set_up_scans_the_law_s_wear_and_each_energy_component() {
        // car1's front tire: friction energy 3 MJ (1 MJ longitudinal, 2 MJ
        // lateral); its law abrades 0.4 %/MJ and predicts 1.3 % of wear.
        let r = KpiRow {
            car: "car1".into(),
            axle: Axle::Front,
            friction_energy_j: 3e6,
            friction_energy_x_j: 1e6,
            friction_energy_y_j: 2e6,
            ..Default::default()
        };
        let law = FRONT_LAW;
        let set_up = |car: &str| Candidate {
            name: format!("set-up: {car}"),
            feature: Feature::Group,
            thresholds: SetUpForm::thresholds(),
            axle: None,
            user: None,
            group: Some(Group {
                car: Some(car.into()),
                wheel: None,
            }),
            scopes: Vec::new(),
        };
        let value = |c: &Candidate, t: f64| candidate_feature(c, &r, None, t, KpiScale::NONE, law);
        let car1 = set_up("car1");
        assert_eq!(car1.thresholds, [0.0, 1.0, 2.0, 3.0]);
        // The law's wear; 0.4 × 3, × 1, × 2 MJ; NaN (older files) is the law's.
        let want = [1.3, 1.2, 0.4, 0.8];
        for (t, w) in want.iter().enumerate() {
            assert!((value(&car1, t as f64) - w).abs() < 1e-12, "form {t}");
        }
        assert_eq!(value(&car1, f64::NAN), 1.3);
        // Another car's set-up, or a form that does not exist: nothing.
        assert_eq!(value(&set_up("car2"), 3.0), 0.0);
        assert_eq!(value(&car1, 4.0), 0.0);
        assert_eq!(value(&car1, 0.5), 0.0);
        let names: Vec<String> = (0..4)
            .map(|t| Feature::Group.format_threshold(t as f64))
            .collect();
        assert_eq!(
            names,
            [
                "the law's wear",
                "energy",
                "longitudinal energy",
                "lateral energy"
            ]
        );
    }

    #[test]
    fn a_wheel_positions_set_up_is_read_as_the_tire_that_wears_more() {
        let set_up = |car: Option<&str>, wheel: Option<Wheel>| Candidate {
            name: String::new(),
            feature: Feature::Group,
            thresholds: vec![f64::NAN],
            axle: None,
            user: None,
            group: Some(Group {
                car: car.map(str::to_string),
                wheel,
            }),
            scopes: Vec::new(),
        };
        // FL on every car is FR on every car with the sign turned (one law per axle).
        assert!(set_up(None, Some(Wheel::FL)).adds_wear_only());
        assert!(set_up(None, Some(Wheel::RR)).adds_wear_only());
        // A car, or one car's wheel, has no such twin: it may wear less.
        assert!(!set_up(Some("car1"), None).adds_wear_only());
        assert!(!set_up(Some("car1"), Some(Wheel::FL)).adds_wear_only());
    }

    /// The diagnosis names a term's tires as the validation names a
    /// planted effect's, so that the two can be compared.
    #[test]
    fn scopes_are_named_as_the_generator_names_them() {
        use crate::sim::generated::Scope as Planted;
        let named = |car: Option<&str>, wheel: Option<Wheel>, axle: Option<Axle>| {
            Candidate {
                name: String::new(),
                feature: Feature::HotSurfaceEnergy,
                thresholds: Vec::new(),
                axle,
                user: None,
                group: (car.is_some() || wheel.is_some()).then(|| Group {
                    car: car.map(str::to_string),
                    wheel,
                }),
                scopes: Vec::new(),
            }
            .scope_description()
        };
        let cases = [
            (Planted::All, named(None, None, None), "every tire"),
            (
                Planted::Axle { axle: Axle::Rear },
                named(None, None, Some(Axle::Rear)),
                "the rear axle",
            ),
            (
                Planted::Wheel { wheel: Wheel::FL },
                named(None, Some(Wheel::FL), None),
                "the FL tire of every car",
            ),
            (
                Planted::Car { car: 1 },
                named(Some("car2"), None, None),
                "car2",
            ),
            (
                Planted::CarAxle {
                    car: 1,
                    axle: Axle::Front,
                },
                named(Some("car2"), None, Some(Axle::Front)),
                "car2's front axle",
            ),
        ];
        for (planted, term, words) in cases {
            assert_eq!(planted.describe(), words);
            assert_eq!(term, words);
        }
        assert_eq!(named(Some("car3"), Some(Wheel::RR), None), "car3's RR tire");
    }

    #[test]
    fn terms_are_charged_at_the_law_abrasion() {
        // A front tire whose law abrades 0.4 %/MJ over an energy term of
        // 2.5 MJ (its raw friction energy is 3 MJ), on a road with Ra_micro
        // 0.02 mm and kurtosis 3.5, in 40 °C air.
        let r = KpiRow {
            axle: Axle::Front,
            friction_energy_j: 3e6,
            ra_micro_mm: 0.02,
            kurtosis: 3.5,
            t_air_avg_c: 40.0,
            ..Default::default()
        };
        let law = FRONT_LAW;
        let rows = vec![&r];
        let lib = library(&rows);
        let named = |name: &str| lib.iter().find(|c| c.name == name).expect(name);
        let kpi = |col: &'static str| {
            lib.iter()
                .find(|c| c.feature == Feature::Kpi(col))
                .expect(col)
        };
        let mut m = EnergyMaps::new();
        m.add(92.0, 100.0, 1.0, 2e6); // surface bin 90–95 °C
        m.add(72.0, 100.0, 1.0, 1e6); // surface bin 70–75 °C
        let value =
            |c: &Candidate, t: f64, scale| candidate_feature(c, &r, Some(&m), t, scale, law);
        // Road: 2.5 MJ × (0.02 − 0.005)/0.01 = 3.75; nothing on the other axle.
        let both = named("road abrasion (energy on micro-rough roads)");
        assert!((value(both, 0.005, KpiScale::NONE) - 3.75).abs() < 1e-12);
        let rear = named("road abrasion (energy on micro-rough roads), rear axle");
        assert_eq!(value(rear, 0.005, KpiScale::NONE), 0.0);
        // Squared: 2.5 MJ × 1.5² = 5.625.
        let squared = named("road abrasion (energy × squared micro-roughness)");
        assert!((value(squared, 0.005, KpiScale::NONE) - 5.625).abs() < 1e-12);
        // A road index: 2.5 MJ × (3.5 − 3.0)/0.25 = 5.
        assert!(kpi("kurtosis").feature.track_level());
        let scale = |mean, sd| KpiScale {
            mean,
            sd,
            ..KpiScale::NONE
        };
        assert!((value(kpi("kurtosis"), f64::NAN, scale(3.0, 0.25)) - 5.0).abs() < 1e-12);
        // A mechanism: 0.4 %/MJ × the 2 MJ with the surface above 80 °C = 0.8.
        let hot = named("thermal degradation (energy with a hot surface)");
        assert!((value(hot, 80.0, KpiScale::NONE) - 0.8).abs() < 1e-12);
        // A generic KPI stays on the raw energy: 3 MJ × (40 − 30)/5 = 6.
        assert!((value(kpi("t_air_avg_c"), f64::NAN, scale(30.0, 5.0)) - 6.0).abs() < 1e-12);
        // Held within the range scored: 40 °C air against rows of 20–35 °C
        // counts as 35 °C, 3 MJ × (35 − 30)/5 = 3.
        let seen = KpiScale {
            min: 20.0,
            max: 35.0,
            ..scale(30.0, 5.0)
        };
        assert!((value(kpi("t_air_avg_c"), f64::NAN, seen) - 3.0).abs() < 1e-12);
    }

    #[test]
    fn pair_candidates_sum_the_quadrant_beyond_both_thresholds() {
        // combined_slip:t_surface_c, coarse bins [0.02 + 0.01·i, 0.03 +
        // 0.01·i) and [45 + 5·j, 50 + 5·j) °C, 8 × 8 cells: 2 MJ at (4, 2) =
        // slip [0.06, 0.07) at 55–60 °C (cell 34), 1 MJ at (1, 7) = slip
        // [0.03, 0.04) above 80 °C (cell 15).
        use crate::kpi::cpu::condition_map::{ConditionMaps, pair_name};
        let pair = (0..N_PAIRS)
            .find(|&p| pair_name(p) == "combined_slip:t_surface_c")
            .unwrap();
        let mut cm = ConditionMaps::default();
        let before: usize = (0..pair)
            .map(|p| {
                let (a, b) = pair_conditions(p);
                CONDITIONS[a].coarse.n * CONDITIONS[b].coarse.n
            })
            .sum();
        cm.pairs_j[before + 34] = 2e6;
        cm.pairs_j[before + 15] = 1e6;
        assert_eq!(cm.pair_map(pair)[34], 2e6);
        let mut m = EnergyMaps::new();
        m.conditions = Some(Box::new(cm));
        let r = KpiRow::default();
        let f = |first_above, second_above, theta: f64| {
            let feature_ = Feature::PairEnergy {
                pair,
                first_above,
                second_above,
            };
            feature(feature_, &r, Some(&m), theta, KpiScale::NONE)
        };
        // θ index k = (i − 1)·7 + (j − 1): k 23 is edges (i 4, j 3) = (0.06, 60 °C).
        assert_eq!(pair_thresholds(pair, 23.0), Some((4, 3)));
        let named = Feature::PairEnergy {
            pair,
            first_above: true,
            second_above: false,
        };
        assert_eq!(named.format_threshold(23.0), "(0.06000, 60.00 °C)");
        let close = |a: f64, b: f64| (a - b).abs() < 1e-9;
        // Slip ≥ 0.06 and surface < 60 °C holds (4, 2): 2 MJ.
        assert!(close(f(true, false, 23.0), 2.0));
        // Slip ≥ 0.06 and surface ≥ 60 °C: nothing.
        assert!(close(f(true, true, 23.0), 0.0));
        // Slip < 0.04 (i 2) and surface ≥ 80 °C (j 7): k = 1·7 + 6 = 13: 1 MJ.
        assert!(close(f(false, true, 13.0), 1.0));
        // Slip < 0.07 (i 5) and surface ≥ 55 °C (j 2): k = 4·7 + 1 = 29: both, 3 MJ.
        assert!(close(f(false, true, 29.0), 3.0));
        // Outside the grid, or maps without pairs: undefined.
        assert!(f(true, true, 49.0).is_nan() && f(true, true, 0.5).is_nan());
        let mut old = m.clone();
        if let Some(cm) = old.conditions.as_mut() {
            cm.pairs_held = false;
        }
        let old_value = feature(named, &r, Some(&old), 23.0, KpiScale::NONE);
        assert!(old_value.is_nan());
        // A named mechanism's point on one side names the pair's mechanism.
        let quadrant = |name: &str, first_above, second_above| {
            let pair = (0..N_PAIRS).find(|&p| pair_name(p) == name).unwrap();
            Feature::PairEnergy {
                pair,
                first_above,
                second_above,
            }
            .mechanism()
        };
        assert_eq!(
            quadrant("combined_slip:t_surface_c", true, true),
            Some("thermal")
        );
        assert_eq!(quadrant("combined_slip:t_surface_c", true, false), None);
        assert_eq!(
            quadrant("combined_slip:t_bulk_c", false, false),
            Some("graining")
        );
        assert_eq!(quadrant("combined_slip:t_bulk_c", true, true), None);
        // Sliding speed above is fast sliding, not a simulator mechanism.
        assert_eq!(quadrant("sliding_speed_mps:t_surface_c", true, false), None);
        // Every pair and quadrant is a candidate on every scope.
        let cars = vec!["car1".to_string()];
        let generated = pair_candidates(&cars);
        assert_eq!(generated.len(), N_PAIRS * 4);
        assert!(
            generated
                .iter()
                .all(|c| c.thresholds.len() == 49 && c.scopes.len() == 10)
        );
    }

    #[test]
    fn band_candidates_sum_the_energy_between_their_ends() {
        // Slip ratio: 30 bins 0.02 wide from −0.3; band ends every third
        // inner edge (3, 6, …, 27: −0.24, −0.18, …, 0.24), 9 ends, 36 bands.
        // 2 MJ in bin 20 ([0.10, 0.12)), 1 MJ in bin 5 ([−0.20, −0.18)),
        // 4 MJ in bin 29 (0.28 and above).
        use crate::kpi::cpu::condition_map::ConditionMaps;
        let slip = ConditionMaps::condition_index("slip_ratio").unwrap();
        assert_eq!(band_edges(slip), vec![3, 6, 9, 12, 15, 18, 21, 24, 27]);
        let mut cm = ConditionMaps::default();
        let o: usize = CONDITIONS[..slip].iter().map(|c| c.bins.n).sum();
        cm.energy_j[0][o + 20] = 2e6;
        cm.energy_j[0][o + 5] = 1e6;
        cm.energy_j[0][o + 29] = 4e6;
        let mut m = EnergyMaps::new();
        m.conditions = Some(Box::new(cm));
        let r = KpiRow::default();
        let band = Feature::BandEnergy {
            condition: slip,
            component: Component::Total,
        };
        let f = |theta: f64| feature(band, &r, Some(&m), theta, KpiScale::NONE);
        let close = |a: f64, b: f64| (a - b).abs() < 1e-9;
        // Index k runs over the first end, then the second: k 0 is (3, 6),
        // k 7 is (3, 27), k 8 is (6, 9), k 35 is (24, 27).
        assert_eq!(band_thresholds(slip, 0.0), Some((3, 6)));
        assert_eq!(band_thresholds(slip, 7.0), Some((3, 27)));
        assert_eq!(band_thresholds(slip, 8.0), Some((6, 9)));
        assert_eq!(band_thresholds(slip, 35.0), Some((24, 27)));
        assert_eq!(band_thresholds(slip, 36.0), None);
        assert_eq!(band_thresholds(slip, 0.5), None);
        // [−0.24, −0.18) holds bin 5: 1 MJ; [−0.24, 0.24) bins 5 and 20: 3 MJ.
        assert!(close(f(0.0), 1.0));
        assert!(close(f(7.0), 3.0));
        // [−0.18, −0.12) and [0.12, 0.18): nothing; [0.06, 0.12) = (18, 21), bin 20.
        assert!(close(f(8.0), 0.0));
        let k = (0..36)
            .find(|&k| band_thresholds(slip, k as f64) == Some((18, 21)))
            .unwrap();
        assert!(close(f(k as f64), 2.0));
        // The top bin (beyond every end) is in no band.
        let all: f64 = (0..36).map(|k| f(k as f64)).fold(0.0, f64::max);
        assert!(close(all, 3.0));
        assert_eq!(band.format_threshold(0.0), "-0.2400 and -0.1800");
        // Every band is listed once, ends increasing, inside the bins.
        for (c, cd) in CONDITIONS.iter().enumerate() {
            let edges = band_edges(c);
            assert!(edges.len() >= 2 && edges.len() <= BAND_EDGES, "{}", cd.name);
            assert!(edges.windows(2).all(|w| w[0] < w[1]) && edges[0] > 0);
            assert!(*edges.last().unwrap() < cd.bins.n);
            let n = edges.len() * (edges.len() - 1) / 2;
            let mut seen: Vec<(usize, usize)> = (0..n)
                .map(|k| band_thresholds(c, k as f64).unwrap())
                .collect();
            assert!(seen.iter().all(|(a, b)| a < b));
            seen.sort();
            seen.dedup();
            assert_eq!(seen.len(), n);
            assert_eq!(band_thresholds(c, n as f64), None);
        }
        // Without condition maps the term is undefined.
        assert!(feature(band, &r, Some(&EnergyMaps::new()), 0.0, KpiScale::NONE).is_nan());
        // Every condition and component is a band candidate on every scope.
        let cars = vec!["car1".to_string()];
        let generated = band_candidates(&cars);
        assert_eq!(generated.len(), CONDITIONS.len() * 3);
        assert!(generated.iter().all(|c| c.scopes.len() == 10));
        assert_eq!(
            generated[0].name.replace('θ', &band.format_threshold(0.0)),
            "energy with slip_ratio between -0.2400 and -0.1800"
        );
    }

    #[test]
    fn a_band_is_scanned_only_where_each_side_holds_energy() {
        // Slip ratio (30 bins, band ends 3, 6, …, 27): 1 MJ in bin 1, 18 in
        // bin 10, 1 in bin 25 on the rear tire; 50 MJ in bin 28 on the
        // front one, which a rear-axle band does not count. Each side must
        // hold 5 % of the rear's 20 MJ: 1 MJ.
        use crate::kpi::cpu::condition_map::ConditionMaps;
        let slip = ConditionMaps::condition_index("slip_ratio").unwrap();
        let o: usize = CONDITIONS[..slip].iter().map(|c| c.bins.n).sum();
        let maps = |bins: &[(usize, f64)]| {
            let mut cm = ConditionMaps::default();
            for &(b, mj) in bins {
                cm.energy_j[0][o + b] = mj * 1e6;
            }
            let mut m = EnergyMaps::new();
            m.conditions = Some(Box::new(cm));
            m
        };
        let rear = maps(&[(1, 1.0), (10, 18.0), (25, 1.0)]);
        let front = maps(&[(28, 50.0)]);
        let rows = [
            KpiRow {
                axle: Axle::Rear,
                ..Default::default()
            },
            KpiRow {
                axle: Axle::Front,
                ..Default::default()
            },
        ];
        let refs: Vec<&KpiRow> = rows.iter().collect();
        let band = Candidate {
            name: "band".into(),
            feature: Feature::BandEnergy {
                condition: slip,
                component: Component::Total,
            },
            thresholds: vec![],
            axle: Some(Axle::Rear),
            user: None,
            group: None,
            scopes: Vec::new(),
        };
        let e = band
            .band_energy(&refs, &[Some(&rear), Some(&front)])
            .unwrap();
        assert!((e.iter().sum::<f64>() - 20e6).abs() < 1e-3);
        let index = |lo: usize, hi: usize| {
            (0..36)
                .find(|&k| band_thresholds(slip, k as f64) == Some((lo, hi)))
                .unwrap() as f64
        };
        // (3, 6): 1 MJ below, 19 above; (3, 24): 1 and 1: both scanned.
        assert!(band_admissible(&e, slip, index(3, 6)));
        assert!(band_admissible(&e, slip, index(3, 24)));
        // (6, 27): nothing above 27 on the rears (the front's 50 MJ does not
        // count); (6, 9): 1 below, 19 above — but (12, 15): 19 below, 1 above.
        assert!(!band_admissible(&e, slip, index(6, 27)));
        assert!(band_admissible(&e, slip, index(12, 15)));
        // 0.9 MJ below is short of 5 % of 19.9 MJ.
        let thin = maps(&[(1, 0.9), (10, 18.0), (25, 1.0)]);
        let e = band.band_energy(&refs, &[Some(&thin), None]).unwrap();
        assert!(!band_admissible(&e, slip, index(3, 6)));
        // No maps on the band's tires: nothing to scan on; other kinds: None.
        assert!(band.band_energy(&refs, &[None, Some(&front)]).is_none());
        let mut both = band.clone();
        both.axle = None;
        // On both axles (70 MJ, 3.5 each side): (12, 27) holds 19 below and
        // the front's 50 above; on the rears alone nothing above.
        let e = both
            .band_energy(&refs, &[Some(&rear), Some(&front)])
            .unwrap();
        assert!(band_admissible(&e, slip, index(12, 27)));
        assert!(!band_admissible(&e, slip, index(3, 6)));
        let rear_only = band
            .band_energy(&refs, &[Some(&rear), Some(&front)])
            .unwrap();
        assert!(!band_admissible(&rear_only, slip, index(12, 27)));
        assert!(!band_admissible(&[0.0; 30], slip, index(3, 6)));
        let not_band = Candidate {
            feature: Feature::HotSurfaceEnergy,
            ..band
        };
        assert!(not_band.band_energy(&refs, &[Some(&rear), None]).is_none());
    }

    #[test]
    fn condition_candidates_sum_the_energy_beyond_the_threshold() {
        // Slip ratio bins are 0.02 wide from −0.3: 2 MJ in bin 20 ([0.10,
        // 0.12)), 1 MJ in bin 5 ([−0.20, −0.18)).
        use crate::kpi::cpu::condition_map::ConditionMaps;
        let slip = ConditionMaps::condition_index("slip_ratio").unwrap();
        let mut cm = ConditionMaps::default();
        let o: usize = CONDITIONS[..slip].iter().map(|c| c.bins.n).sum();
        cm.energy_j[0][o + 20] = 2e6;
        cm.energy_j[0][o + 5] = 1e6;
        let mut m = EnergyMaps::new();
        m.conditions = Some(Box::new(cm));
        let r = KpiRow::default();
        let f = |above: bool, theta: f64| {
            feature(
                Feature::ConditionEnergy {
                    condition: slip,
                    above,
                    component: Component::Total,
                },
                &r,
                Some(&m),
                theta,
                KpiScale::NONE,
            )
        };
        let close = |a: f64, b: f64| (a - b).abs() < 1e-9;
        assert!(close(f(true, 0.1), 2.0));
        assert!(close(f(true, 0.12), 0.0));
        assert!(close(f(true, -0.2), 3.0));
        assert!(close(f(false, -0.1), 1.0));
        assert!(close(f(false, -0.2), 0.0));
        // A component's candidate sums that component's map: 0.5 MJ of the
        // 2 MJ in bin 20 is lateral.
        let mut lateral = m.clone();
        if let Some(cm) = lateral.conditions.as_mut() {
            cm.energy_j[2][o + 20] = 0.5e6;
        }
        let lat = Feature::ConditionEnergy {
            condition: slip,
            above: true,
            component: Component::Lateral,
        };
        assert!(close(
            feature(lat, &r, Some(&lateral), 0.1, KpiScale::NONE),
            0.5
        ));
        assert!(close(
            feature(lat, &r, Some(&lateral), 0.12, KpiScale::NONE),
            0.0
        ));
        // Without condition maps (an older extraction) the term is undefined.
        assert!(
            feature(
                Feature::ConditionEnergy {
                    condition: slip,
                    above: true,
                    component: Component::Total,
                },
                &r,
                Some(&EnergyMaps::new()),
                0.1,
                KpiScale::NONE
            )
            .is_nan()
        );
        // The generated space: every condition and component both ways,
        // less the points the named mechanisms stand for, each one candidate
        // scanned over 7 + 3·2 scopes (both axles, each axle, each wheel,
        // and each of two cars and its axles).
        let cars = ["car1".to_string(), "car2".to_string()];
        let generated = condition_candidates(&cars);
        assert_eq!(
            generated.len(),
            (2 * CONDITIONS.len() - NAMED_CONDITIONS.len()) * 3
        );
        assert!(generated.iter().all(|c| c.scopes.len() == 7 + 3 * 2));
        let generated: Vec<Candidate> = generated.iter().flat_map(|c| c.resolved()).collect();
        for (name, above, _) in NAMED_CONDITIONS {
            let c = ConditionMaps::condition_index(name).unwrap();
            for component in Component::ALL {
                let named = Feature::ConditionEnergy {
                    condition: c,
                    above,
                    component,
                };
                assert!(!generated.iter().any(|g| g.feature == named));
            }
        }
        // A wheel's candidate is the same energy on that wheel's tires (of
        // every car), zero on the others — its axle partner included.
        // KpiRow's default wheel is FL (front); the law's abrasion is 1.
        let law = LawRow {
            abrasion: 1.0,
            energy_mj: 0.0,
            wear_pct: 0.0,
        };
        let scoped = |suffix: &str| {
            let name = format!("energy with slip_ratio above θ{suffix}");
            generated
                .iter()
                .find(|c| c.name == name)
                .expect("generated")
        };
        let on = |c: &Candidate, wheel: Wheel| {
            let r = KpiRow {
                wheel,
                axle: wheel.axle(),
                ..KpiRow::default()
            };
            candidate_feature(c, &r, Some(&m), 0.1, KpiScale::NONE, law)
        };
        for w in Wheel::ALL {
            let c = scoped(&format!(", {w} wheel"));
            for other in Wheel::ALL {
                let want = if other == w { 2.0 } else { 0.0 };
                assert!(close(on(c, other), want), "{} on {other}", c.name);
            }
        }
        assert!(close(on(scoped(", front axle"), Wheel::FR), 2.0));
        assert!(close(on(scoped(", front axle"), Wheel::RL), 0.0));
        // A car's scope: that car's tires (its axle's, for a car-axle
        // scope), zero on the other car's.
        let on_car = |c: &Candidate, car: &str, wheel: Wheel| {
            let r = KpiRow {
                car: car.into(),
                wheel,
                axle: wheel.axle(),
                ..KpiRow::default()
            };
            candidate_feature(c, &r, Some(&m), 0.1, KpiScale::NONE, law)
        };
        let car2 = scoped(", car2");
        assert!(close(on_car(car2, "car2", Wheel::RL), 2.0));
        assert!(close(on_car(car2, "car1", Wheel::RL), 0.0));
        let car2_rear = scoped(", car2, rear axle");
        assert!(close(on_car(car2_rear, "car2", Wheel::RR), 2.0));
        assert!(close(on_car(car2_rear, "car2", Wheel::FL), 0.0));
        assert!(close(on_car(car2_rear, "car1", Wheel::RR), 0.0));
    }

    #[test]
    fn graining_uses_the_cold_tread_lateral_energy() {
        // Graining: lateral share × energy of the map bins with a cold tread bulk.
        let mut m = EnergyMaps::new();
        m.add(62.0, 92.0, 1.0, 2e6); // bulk (62.5 + 92.5)/2 = 77.5 °C
        m.add(90.0, 100.0, 1.0, 1e6); // bulk 96.25 °C
        let g = KpiRow {
            friction_energy_j: 3e6,
            friction_energy_y_j: 1.5e6,
            ..Default::default()
        };
        let f = feature(
            Feature::ColdTreadLateralEnergy,
            &g,
            Some(&m),
            80.0,
            KpiScale::NONE,
        );
        assert!((f - 0.5 * 2.0).abs() < 1e-12, "{f}");
    }
}
