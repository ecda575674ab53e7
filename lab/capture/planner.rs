//! The teams the capture study compares (`--planners`): a built-in planner, or a shipped
//! trained policy (`policy:<name>`, [`crate::policy`]) driving the robots from what each
//! knows.

use lasertag_core::planner::PlannerKind;
use lasertag_core::world::MatchConfig;

use crate::policy;

/// The planners compared unless asked: the paper's three.
pub const DEFAULT: &str = "coordinated,search,baseline";

/// What drives the robots in one setting of the study.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Planner {
    BuiltIn(PlannerKind),
    /// A shipped policy, by name (without the `policy:` prefix).
    Policy(String),
}

impl Planner {
    pub const BASELINE: Planner = Planner::BuiltIn(PlannerKind::Baseline);
    pub const COORDINATED: Planner = Planner::BuiltIn(PlannerKind::Coordinated);

    /// `coordinated`, `search`, `baseline` or `policy:<name>` (a shipped policy).
    pub fn parse(text: &str) -> Result<Planner, String> {
        if let Some(name) = text.strip_prefix(policy::PREFIX) {
            if !policy::is_shipped(name) {
                return Err(format!(
                    "{text}: no shipped policy {name:?} (the shipped ones: {})",
                    policy::shipped_names()
                ));
            }
            return Ok(Planner::Policy(name.to_string()));
        }
        match text {
            "coordinated" => Ok(Planner::COORDINATED),
            "search" => Ok(Planner::BuiltIn(PlannerKind::Search)),
            "baseline" => Ok(Planner::BASELINE),
            _ => Err(format!(
                "{text:?}: the planners are coordinated, search, baseline and policy:<name> \
                 (the shipped policies: {})",
                policy::shipped_names()
            )),
        }
    }

    /// A comma-separated list of planners: each once, `baseline` and `coordinated` among
    /// them (the summary's ratios and tests are against those two).
    pub fn parse_list(text: &str) -> Result<Vec<Planner>, String> {
        let planners = text
            .split(',')
            .map(|p| Planner::parse(p.trim()))
            .collect::<Result<Vec<_>, _>>()?;
        for (i, p) in planners.iter().enumerate() {
            if planners[..i].contains(p) {
                return Err(format!("{} is listed twice", p.name()));
            }
        }
        if !planners.contains(&Planner::BASELINE) || !planners.contains(&Planner::COORDINATED) {
            return Err(
                "the list must hold baseline and coordinated (the summary compares with them)"
                    .into(),
            );
        }
        Ok(planners)
    }

    /// As the CSV files, plots and `--planners` spell it.
    pub fn name(&self) -> String {
        match self {
            Planner::BuiltIn(kind) => kind.name().to_string(),
            Planner::Policy(name) => format!("{}{name}", policy::PREFIX),
        }
    }

    /// Sets `config`'s team to it: a policy's robots are driven from outside, by the run.
    pub fn apply(&self, config: &mut MatchConfig) {
        match self {
            Planner::BuiltIn(kind) => {
                config.planner = *kind;
                config.policy = None;
            }
            Planner::Policy(name) => {
                config.planner = PlannerKind::Api;
                config.policy = Some(name.clone());
            }
        }
    }
}

/// The `planners` parameter of a study.
pub fn list_name(planners: &[Planner]) -> String {
    let names: Vec<String> = planners.iter().map(Planner::name).collect();
    names.join(",")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn planner_lists_read_back_and_bad_ones_say_why() {
        let list = Planner::parse_list("coordinated,search,baseline,policy:learned").unwrap();
        assert_eq!(list[3], Planner::Policy("learned".into()));
        assert_eq!(
            list_name(&list),
            "coordinated,search,baseline,policy:learned"
        );
        assert_eq!(Planner::parse_list(DEFAULT).unwrap().len(), 3);
        for (bad, says) in [
            ("coordinated,baseline,policy:nope", "policy:learned"),
            ("coordinated,baseline,clever", "policy:<name>"),
            ("coordinated,baseline,baseline", "twice"),
            ("coordinated,policy:learned", "must hold baseline"),
        ] {
            let e = Planner::parse_list(bad).unwrap_err();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }
}
