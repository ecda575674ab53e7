//! A match's settings and map from Python values: the fields of `POST /api/matches` and of
//! a map file (docs/api.md, docs/map-format.md), checked as the server checks them, each
//! error naming its field.
//!
//! The server builds its `MatchConfig` from JSON (`server/protocol.rs`, `CreateMatch`); the
//! engine builds the same one from a dict, in the same order (odometry before the
//! localiser, whose defaults follow it). The counts are only read here: the core's engine
//! checks them against their bounds (`lasertag_core::env::engine`) before anything is
//! allocated for them.

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use lasertag_core::bots::BotKind;
use lasertag_core::env::engine;
use lasertag_core::localise;
use lasertag_core::planner::PlannerKind;
use lasertag_core::settings::{Group, Kind, Value};
use lasertag_core::sim::map_rules::MapSpec;
use lasertag_core::sim::{Odometry, Physics};
use lasertag_core::world::{MatchConfig, Placement};

fn refuse(field: &str, message: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(format!("{field}: {message}"))
}

/// `value` at `field` as `T`, or an error naming the field.
fn get<'py, T: FromPyObjectOwned<'py>>(value: &Bound<'py, PyAny>, field: &str) -> PyResult<T> {
    value.extract().map_err(|_| {
        let type_name = value
            .get_type()
            .name()
            .map_or_else(|_| "?".to_owned(), |n| n.to_string());
        refuse(
            field,
            format!("a {type_name} is not {}", std::any::type_name::<T>()),
        )
    })
}

/// A map object (docs/map-format.md) as the core's rules read it.
pub fn map_spec(map: &Bound<'_, PyDict>) -> PyResult<MapSpec> {
    let mut spec = MapSpec::default();
    let mut seen = Vec::new();
    for (key, value) in map.iter() {
        let key: String = get(&key, "map")?;
        let at = format!("map.{key}");
        match key.as_str() {
            "name" => spec.name = get(&value, &at)?,
            "width" => spec.width = get(&value, &at)?,
            "height" => spec.height = get(&value, &at)?,
            "obstacles" => spec.obstacles = get(&value, &at)?,
            "robot_spawns" => spec.robot_spawns = get(&value, &at)?,
            "opponent_spawns" => spec.opponent_spawns = get(&value, &at)?,
            "landmarks" => spec.landmarks = get(&value, &at)?,
            _ => {
                return Err(refuse(
                    &at,
                    "unknown field, expected one of name, width, height, obstacles, \
                     robot_spawns, opponent_spawns, landmarks",
                ));
            }
        }
        seen.push(key);
    }
    for required in [
        "name",
        "width",
        "height",
        "obstacles",
        "robot_spawns",
        "opponent_spawns",
    ] {
        if !seen.iter().any(|k| k == required) {
            return Err(refuse(&format!("map.{required}"), "missing"));
        }
    }
    Ok(spec)
}

/// `base` with the fields `value` (a dict) names, each checked by the group's declaration.
fn group<G: Group>(base: G, value: &Bound<'_, PyAny>) -> PyResult<G> {
    let dict = value
        .cast::<PyDict>()
        .map_err(|_| refuse(G::NAME, "must be a dict of settings"))?;
    let mut out = base;
    for (key, v) in dict.iter() {
        let name: String = get(&key, G::NAME)?;
        let at = format!("{}.{name}", G::NAME);
        let Some(field) = G::field(&name) else {
            let known: Vec<_> = G::FIELDS.iter().map(|f| f.name).collect();
            return Err(refuse(
                &at,
                format!("unknown setting (known: {})", known.join(", ")),
            ));
        };
        if v.is_none() {
            continue;
        }
        let value = match field.kind {
            Kind::Integer => {
                // 5.0 stands for 5, as JSON tools write it (the server takes it too).
                let x: f64 = get(&v, &at)?;
                if x.fract() != 0.0 || !x.is_finite() {
                    return Err(refuse(&at, format!("{x} is not an integer")));
                }
                Value::Integer(x as i64)
            }
            Kind::Number => Value::Number(get(&v, &at)?),
            Kind::Bool => Value::Bool(get(&v, &at)?),
        };
        out.set(&name, value)
            .map_err(|e| PyValueError::new_err(e.within(G::NAME).to_string()))?;
    }
    Ok(out)
}

fn points<const N: usize>(value: &Bound<'_, PyAny>, field: &str) -> PyResult<Vec<[f32; N]>> {
    let raw: Vec<[f64; N]> = get(value, field)?;
    raw.iter()
        .enumerate()
        .map(|(i, p)| {
            if p.iter().all(|v| v.is_finite()) {
                Ok(p.map(|v| v as f32))
            } else {
                Err(refuse(&format!("{field}[{i}]"), "is not a finite point"))
            }
        })
        .collect()
}

/// The planner values of the shipped policies, `policy:<name>` each, comma-separated.
fn shipped_policies() -> String {
    let names: Vec<String> = lasertag_policy::SHIPPED
        .iter()
        .map(|(name, _)| format!("policy:{name}"))
        .collect();
    names.join(", ")
}

/// The shipped policy that `planner` (one name, or one per robot) names as `policy:<name>`,
/// if any. Refused: an unknown name (only the policies built into the package run
/// in-process; one uploaded to a server plays there), and a policy in a list, as a policy
/// drives the whole team.
fn policy_planner(names: &[String]) -> PyResult<Option<String>> {
    let Some(named) = names.iter().find(|n| n.starts_with("policy:")) else {
        return Ok(None);
    };
    if names.len() > 1 {
        return Err(refuse(
            "planner",
            format!(
                "{named:?} in a list: a policy drives the whole team (give planner={named:?} alone)"
            ),
        ));
    }
    let name = &named["policy:".len()..];
    if lasertag_policy::shipped(name).is_none() {
        return Err(refuse(
            "planner",
            format!(
                "{named:?}: no shipped policy {name:?}; the in-process engine runs only the \
                 policies built into the package ({}); a policy uploaded to a server plays \
                 only on that server",
                shipped_policies()
            ),
        ));
    }
    Ok(Some(name.to_string()))
}

/// The match of a research environment: robots driven by the policy (`planner: api`),
/// opponents by bots, and the settings `settings` gives.
pub fn match_config(settings: &Bound<'_, PyDict>) -> PyResult<MatchConfig> {
    let mut config = MatchConfig {
        planner: PlannerKind::Api,
        ..MatchConfig::default()
    };
    let mut odometry = None;
    let mut localiser = None;
    let (mut robot_starts, mut opponent_starts) = (Vec::new(), Vec::new());
    let mut random = false;
    let mut planners = None;
    for (key, value) in settings.iter() {
        let key: String = get(&key, "settings")?;
        if value.is_none() {
            continue;
        }
        match key.as_str() {
            "robots" => config.robots = get(&value, &key)?,
            "opponents" => config.opponents = get(&value, &key)?,
            "opponent_bot" => {
                let name: String = get(&value, &key)?;
                config.opponent_bot = match name.as_str() {
                    "wander" => BotKind::Wander,
                    "evade" => BotKind::Evade,
                    "idle" => BotKind::Idle,
                    _ => {
                        return Err(refuse(
                            &key,
                            format!("{name:?}: the bots are wander, evade, idle"),
                        ));
                    }
                };
            }
            "time_limit_s" => {
                let s: f64 = get(&value, &key)?;
                config.time_limit_ticks = engine::time_limit_ticks(s)
                    .map_err(|e| PyValueError::new_err(e.to_string()))?;
            }
            "placement" => {
                let name: String = get(&value, &key)?;
                random = match name.as_str() {
                    "spawns" => false,
                    "random" => true,
                    _ => {
                        return Err(refuse(
                            &key,
                            format!("{name:?}: the placements are spawns, random"),
                        ));
                    }
                };
            }
            "robot_starts" => robot_starts = points::<3>(&value, &key)?,
            "opponent_starts" => {
                opponent_starts = points::<2>(&value, &key)?;
            }
            "localisation" => config.localisation = get(&value, &key)?,
            // The built-in planners drive the robots and the actions are ignored: the
            // paper's planners measured on the environment's own episodes.
            "planner" => {
                // One name for the team, or one per robot (a mixed team: the built-in ones
                // plan, the `api` ones take the actions).
                let names: Vec<String> = match get::<String>(&value, &key) {
                    Ok(name) => vec![name],
                    Err(_) => get(&value, &key)?,
                };
                // A shipped trained policy drives the whole team: its robots are driven from
                // outside, the engine giving them the policy's orders (lib.rs).
                if let Some(policy) = policy_planner(&names)? {
                    config.planner = PlannerKind::Api;
                    config.policy = Some(policy);
                    config.outside_robots = Vec::new();
                    planners = None;
                    continue;
                }
                let kinds = names
                    .iter()
                    .map(|name| match name.as_str() {
                        "api" => Ok(PlannerKind::Api),
                        "coordinated" => Ok(PlannerKind::Coordinated),
                        "search" => Ok(PlannerKind::Search),
                        "baseline" => Ok(PlannerKind::Baseline),
                        _ => Err(refuse(
                            &key,
                            format!(
                                "{name:?}: the planners are api, coordinated, search, \
                                 baseline and policy:<name> ({})",
                                shipped_policies()
                            ),
                        )),
                    })
                    .collect::<PyResult<Vec<_>>>()?;
                let built_in: Vec<PlannerKind> = kinds
                    .iter()
                    .copied()
                    .filter(|k| *k != PlannerKind::Api)
                    .collect();
                if built_in.windows(2).any(|w| w[0] != w[1]) {
                    return Err(refuse(
                        &key,
                        "the robots a team plans share one planner (the others are \"api\")",
                    ));
                }
                config.planner = built_in.first().copied().unwrap_or(PlannerKind::Api);
                config.outside_robots = if kinds.len() > 1 && config.planner != PlannerKind::Api {
                    kinds.iter().map(|k| *k == PlannerKind::Api).collect()
                } else {
                    Vec::new()
                };
                planners = Some(kinds.len());
            }
            "tracker" => config.tracker = group(config.tracker.clone(), &value)?,
            "coordination" => config.coordination = group(config.coordination.clone(), &value)?,
            "radio" => config.radio = group(config.radio.clone(), &value)?,
            "odometry" => odometry = Some(value),
            "localiser" => localiser = Some(value),
            _ => {
                return Err(refuse(
                    &key,
                    "not a setting of the in-process engine (it takes robots, opponents, \
                     opponent_bot, time_limit_s, placement, robot_starts, opponent_starts, \
                     localisation, tracker, coordination, radio, odometry, localiser; \
                     vector_env also planner)",
                ));
            }
        }
    }
    if let Some(n) = planners
        && n > 1
        && n != config.robots
    {
        return Err(refuse(
            "planner",
            format!(
                "{n} planners for {} robots: give one per robot",
                config.robots
            ),
        ));
    }
    config.placement = if !robot_starts.is_empty() || !opponent_starts.is_empty() {
        Placement::Given {
            robots: robot_starts,
            opponents: opponent_starts.iter().map(|p| [p[0], p[1]]).collect(),
        }
    } else if random {
        Placement::Random
    } else {
        Placement::Spawns
    };
    config.physics = Physics {
        odometry: match odometry {
            Some(v) => group(Odometry::default(), &v)?,
            None => Odometry::default(),
        },
        ..config.physics
    };
    let localiser_base = localise::Settings::for_odometry(&config.physics);
    config.localiser = match localiser {
        Some(v) => group(localiser_base, &v)?,
        None => localiser_base,
    };
    Ok(config)
}
