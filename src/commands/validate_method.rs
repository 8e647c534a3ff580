//! The ways `tslg validate` runs a pairing's campaigns, named from the
//! method's and the search's own names (`tslg_api::Method`,
//! `tslg_api::AdaptiveSearch`): `plain` is the library campaign, an
//! adaptive method adds `-lattice` for a search other than the grid's, and
//! `-guarded` stops under the outside guard (`guarded` alone: the library
//! campaign's). A new method that draws from a library, or a new search, is
//! offered here without an edit.

use tslg_api::{AdaptiveSearch, Method};
use tslg_method::adaptive::AdaptiveSettings;

/// A way of running a pairing's campaigns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ValidateMethod {
    /// A method that draws from a library.
    pub method: Method,
    /// How it searches, if it runs in stages (the grid's otherwise).
    pub search: AdaptiveSearch,
    /// Whether it stops under the outside guard whatever the vehicle.
    pub guarded: bool,
}

impl ValidateMethod {
    /// The library campaign, unguarded: the default.
    pub const PLAIN: Self = ValidateMethod {
        method: Method::Library,
        search: AdaptiveSearch::Grid,
        guarded: false,
    };

    /// Every way, in the order the tables list them: each method a client
    /// may ask for that draws from a library, with each search where it
    /// searches, unguarded and then guarded.
    pub fn all() -> Vec<Self> {
        Method::requestable()
            .filter(|m| m.uses_library())
            .flat_map(|method| {
                let searches: &[AdaptiveSearch] = if method.in_stages() {
                    &AdaptiveSearch::ALL
                } else {
                    &[AdaptiveSearch::Grid]
                };
                searches.iter().flat_map(move |&search| {
                    [false, true].map(|guarded| ValidateMethod {
                        method,
                        search,
                        guarded,
                    })
                })
            })
            .collect()
    }

    /// Its name on the command line and in the tables.
    pub fn name(self) -> String {
        let mut name = match self.method {
            Method::Library => "plain".to_owned(),
            other => other.as_str().to_owned(),
        };
        if self.method.in_stages() && self.search != AdaptiveSearch::Grid {
            name = format!("{name}-{}", self.search.as_str());
        }
        match (self.guarded, name.as_str()) {
            (false, _) => name,
            (true, "plain") => "guarded".to_owned(),
            (true, _) => format!("{name}-guarded"),
        }
    }

    /// The way named `name`, if one is.
    pub fn parse(name: &str) -> Option<Self> {
        Self::all().into_iter().find(|m| m.name() == name)
    }

    /// What it runs, in a line of `--help`.
    pub fn help(self) -> String {
        let mut help = match self.method {
            Method::Library => "the library campaign".to_owned(),
            other => format!("an {other} campaign"),
        };
        if self.method.in_stages() && self.search != AdaptiveSearch::Grid {
            help += &format!(
                ", its search on the {} (docs/adaptive-design.md, \"Fine grids\")",
                self.search.as_str()
            );
        }
        if self.guarded {
            help += ", under the outside guard (docs/statistics.md)";
        }
        help
    }

    /// `--methods`' parser: the names of [`Self::all`].
    pub fn parser() -> impl clap::builder::TypedValueParser<Value = Self> {
        use clap::builder::TypedValueParser as _;
        let names = Self::all()
            .into_iter()
            .map(|m| clap::builder::PossibleValue::new(m.name()).help(m.help()));
        clap::builder::PossibleValuesParser::new(names)
            .map(|name: String| Self::parse(&name).expect("the parser offers names of ways alone"))
    }

    /// The settings of its adaptive campaigns, with estimation stages of
    /// `stage_tests` and the search width they imply.
    pub fn settings(self, stage_tests: u64) -> AdaptiveSettings {
        AdaptiveSettings {
            stage_tests,
            search_width: AdaptiveSettings::fleet_search_width(stage_tests),
            lattice: self.search == AdaptiveSearch::Lattice,
            ..AdaptiveSettings::default()
        }
    }

    /// Whether its campaigns are adaptive (run in stages).
    pub fn adaptive(self) -> bool {
        self.method.in_stages()
    }

    /// The same way without the guard.
    pub fn unguarded(self) -> Self {
        ValidateMethod {
            guarded: false,
            ..self
        }
    }
}

impl std::fmt::Display for ValidateMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ways_keep_the_names_the_tables_and_docs_use() {
        let names: Vec<String> = ValidateMethod::all()
            .into_iter()
            .map(ValidateMethod::name)
            .collect();
        assert_eq!(
            names,
            [
                "plain",
                "guarded",
                "adaptive",
                "adaptive-guarded",
                "adaptive-lattice",
                "adaptive-lattice-guarded"
            ]
        );
        for way in ValidateMethod::all() {
            assert_eq!(ValidateMethod::parse(&way.name()), Some(way));
        }
        assert_eq!(ValidateMethod::parse("ndd"), None);
        assert_eq!(ValidateMethod::parse("plain-lattice"), None);
    }
}
