//! The robot team's planner on the wire: one for the whole team, or one per robot, where
//! each robot is planned by the team's built-in planner or driven from outside (`"api"`).

use serde::{Deserialize, Deserializer, Serialize, de::Error};
use utoipa::ToSchema;
use utoipa::openapi::schema::{ArrayBuilder, OneOfBuilder, Schema};
use utoipa::openapi::{Ref, RefOr};

use lasertag_core::planner::PlannerKind;
use lasertag_core::settings::FieldError;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Planner {
    Coordinated,
    /// The coordinated planner's negotiation, each choice a look-ahead over several view
    /// poses (docs/search-planner.md).
    Search,
    Baseline,
    Idle,
    /// Robots driven from outside (`POST /api/matches/{id}/robots/{rid}/command`, `/act`).
    Api,
}

/// `planner` in a request: one name for the team, a trained policy for the team
/// (`"policy:<name>"`), or one per robot.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PlannerChoice {
    Team(Planner),
    Policy(String),
    PerRobot(Vec<Planner>),
}

/// What names a trained policy in `planner`.
pub const POLICY_PREFIX: &str = "policy:";

impl<'de> Deserialize<'de> for PlannerChoice {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<PlannerChoice, D::Error> {
        // By hand rather than `untagged`, whose error names no variant: say what is wanted.
        let value = serde_json::Value::deserialize(d)?;
        let wanted = "a planner (coordinated, search, baseline, idle, api, or policy:<name> for a trained policy from GET /api/policies) or an array of the built-in ones, one per robot";
        match value {
            serde_json::Value::String(s) if s.starts_with(POLICY_PREFIX) => {
                let name = &s[POLICY_PREFIX.len()..];
                if name.is_empty() {
                    return Err(D::Error::custom(
                        "policy: names no policy; expected policy:<name> (GET /api/policies lists them)",
                    ));
                }
                Ok(PlannerChoice::Policy(name.to_string()))
            }
            serde_json::Value::String(_) => Planner::deserialize(value)
                .map(PlannerChoice::Team)
                .map_err(|e| D::Error::custom(format!("{e}; expected {wanted}"))),
            serde_json::Value::Array(_) => Vec::<Planner>::deserialize(value)
                .map(PlannerChoice::PerRobot)
                .map_err(|e| D::Error::custom(format!("{e}; expected {wanted}"))),
            other => Err(D::Error::custom(format!(
                "invalid value: {other}, expected {wanted}"
            ))),
        }
    }
}

pub(super) fn choice_schema() -> RefOr<Schema> {
    OneOfBuilder::new()
        .item(Ref::from_schema_name("Planner"))
        .item(
            utoipa::openapi::schema::ObjectBuilder::new()
                .schema_type(utoipa::openapi::schema::Type::String)
                .pattern(Some("^policy:.+$"))
                .description(Some("A trained policy the server holds (GET /api/policies) drives every robot")),
        )
        .item(
            ArrayBuilder::new()
                .items(Ref::from_schema_name("Planner"))
                .min_items(Some(1))
                .max_items(Some(super::bounds::ROBOTS.max_integer() as usize)),
        )
        .description(Some(
            "The team's planner, a trained policy (`policy:<name>`) for the whole team, or one built-in planner per robot: the built-in ones must be the same; `api` robots are driven from outside beside them (default coordinated).",
        ))
        .into()
}

/// What a `planner` choice sets of a match.
#[derive(Debug, Clone, PartialEq)]
pub struct Resolved {
    /// The team's planner, when the choice names one.
    pub planner: Option<PlannerKind>,
    /// The robots, when the request or a per-robot list says how many.
    pub robots: Option<usize>,
    /// `MatchConfig::outside_robots`.
    pub outside: Vec<bool>,
    /// `MatchConfig::policy`.
    pub policy: Option<String>,
}

/// The team's planner and which robots are driven from outside, for `robots` robots (when
/// given) — what `MatchConfig::planner` and `MatchConfig::outside_robots` take. Per robot,
/// the list's length sets the robots unless `robots` is given too, when they must agree.
pub fn resolve(
    choice: Option<&PlannerChoice>,
    robots: Option<usize>,
) -> Result<Resolved, FieldError> {
    let refuse = |message: String| FieldError {
        field: "planner".to_string(),
        message,
    };
    match choice {
        None => Ok(Resolved {
            planner: None,
            robots,
            outside: Vec::new(),
            policy: None,
        }),
        Some(PlannerChoice::Team(p)) => Ok(Resolved {
            planner: Some(planner_kind(*p)),
            robots,
            outside: Vec::new(),
            policy: None,
        }),
        Some(PlannerChoice::Policy(name)) => Ok(Resolved {
            planner: Some(PlannerKind::Api),
            robots,
            outside: Vec::new(),
            policy: Some(name.clone()),
        }),
        Some(PlannerChoice::PerRobot(list)) => {
            if list.is_empty() {
                return Err(refuse("an empty list: give one planner per robot".into()));
            }
            if let Some(n) = robots
                && n != list.len()
            {
                return Err(refuse(format!(
                    "{} planners for {n} robots: give one per robot",
                    list.len()
                )));
            }
            let built_in: Vec<Planner> = list
                .iter()
                .copied()
                .filter(|p| *p != Planner::Api)
                .collect();
            if let Some(other) = built_in.iter().find(|p| **p != built_in[0]) {
                return Err(refuse(format!(
                    "{:?} and {:?}: the robots a team plans share one planner (the others are \"api\")",
                    planner_name(planner_kind(built_in[0])),
                    planner_name(planner_kind(*other)),
                )));
            }
            let kind = built_in
                .first()
                .map_or(PlannerKind::Api, |p| planner_kind(*p));
            let outside = if kind == PlannerKind::Api || built_in.len() == list.len() {
                Vec::new()
            } else {
                list.iter().map(|p| *p == Planner::Api).collect()
            };
            Ok(Resolved {
                planner: Some(kind),
                robots: Some(list.len()),
                outside,
                policy: None,
            })
        }
    }
}

pub(crate) fn planner_kind(p: Planner) -> PlannerKind {
    match p {
        Planner::Coordinated => PlannerKind::Coordinated,
        Planner::Search => PlannerKind::Search,
        Planner::Baseline => PlannerKind::Baseline,
        Planner::Idle => PlannerKind::Idle,
        Planner::Api => PlannerKind::Api,
    }
}

/// The planner's name as the API spells it (also the `kind` label of the tick metrics).
pub fn planner_name(p: PlannerKind) -> &'static str {
    p.name()
}

pub(crate) fn planner_dto(p: PlannerKind) -> Planner {
    match p {
        PlannerKind::Coordinated => Planner::Coordinated,
        PlannerKind::Search => Planner::Search,
        PlannerKind::Baseline => Planner::Baseline,
        PlannerKind::Idle => Planner::Idle,
        PlannerKind::Api => Planner::Api,
    }
}

/// What drives one robot, as summaries and states show it: the team's built-in planner,
/// a client of the API, or a person (a pursuer slot).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Controller {
    Coordinated,
    Search,
    Baseline,
    Idle,
    Api,
    /// A trained policy (the match's `policy`).
    Policy,
    Person,
}

/// Each robot's controller in a match set up as `config` is.
pub fn per_robot(config: &lasertag_core::world::MatchConfig) -> Vec<Controller> {
    let seats = config.robots.saturating_sub(config.pursuer_slots);
    (0..config.robots)
        .map(|i| {
            if i >= seats {
                Controller::Person
            } else if config.policy.is_some() && config.planner == PlannerKind::Api {
                Controller::Policy
            } else if config.planner == PlannerKind::Api
                || config.outside_robots.get(i) == Some(&true)
            {
                Controller::Api
            } else {
                match config.planner {
                    PlannerKind::Coordinated => Controller::Coordinated,
                    PlannerKind::Search => Controller::Search,
                    PlannerKind::Baseline => Controller::Baseline,
                    PlannerKind::Idle => Controller::Idle,
                    PlannerKind::Api => Controller::Api,
                }
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn list(names: &[Planner]) -> Option<PlannerChoice> {
        Some(PlannerChoice::PerRobot(names.to_vec()))
    }

    #[test]
    fn a_list_sets_the_team_and_who_is_driven_from_outside() {
        use Planner::{Api, Baseline, Coordinated};
        let r = resolve(list(&[Coordinated, Api]).as_ref(), None).unwrap();
        assert_eq!(
            (r.planner, r.robots),
            (Some(PlannerKind::Coordinated), Some(2))
        );
        assert_eq!(r.outside, [false, true]);
        // All api is the api team; all built-in is the plain team.
        let r = resolve(list(&[Api, Api]).as_ref(), Some(2)).unwrap();
        assert_eq!((r.planner, r.outside.len()), (Some(PlannerKind::Api), 0));
        let r = resolve(list(&[Baseline, Baseline]).as_ref(), None).unwrap();
        assert_eq!(
            (r.planner, r.outside.len()),
            (Some(PlannerKind::Baseline), 0)
        );
        // Disagreements are named.
        let e = resolve(list(&[Coordinated, Baseline]).as_ref(), None).unwrap_err();
        assert!(e.message.contains("share one planner"), "{e:?}");
        let e = resolve(list(&[Coordinated, Api]).as_ref(), Some(3)).unwrap_err();
        assert!(e.message.contains("2 planners for 3 robots"), "{e:?}");
        assert!(resolve(list(&[]).as_ref(), None).is_err());
    }

    #[test]
    fn a_choice_reads_from_a_name_or_a_list_and_says_what_it_wants() {
        let one: PlannerChoice = serde_json::from_str(r#""baseline""#).unwrap();
        assert_eq!(one, PlannerChoice::Team(Planner::Baseline));
        let many: PlannerChoice = serde_json::from_str(r#"["coordinated", "api"]"#).unwrap();
        assert_eq!(
            many,
            PlannerChoice::PerRobot(vec![Planner::Coordinated, Planner::Api])
        );
        let e = serde_json::from_str::<PlannerChoice>("3").unwrap_err();
        assert!(e.to_string().contains("one per robot"), "{e}");
        let e = serde_json::from_str::<PlannerChoice>(r#"["fast"]"#).unwrap_err();
        assert!(e.to_string().contains("unknown variant"), "{e}");
    }
}
