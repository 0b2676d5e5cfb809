//! The prompts: minijinja templates in the repository's `prompts/` folder, compiled into the
//! binary, and the constraint [`vocabulary`] they embed.
//!
//! Templates render with strict undefined behaviour, so a variable missing from the context is an
//! error rather than an empty string in a prompt.

pub mod vocabulary;

use minijinja::syntax::SyntaxConfig;
use minijinja::value::Serde;
use minijinja::{Environment, UndefinedBehavior};
use serde::Serialize;

/// Every template, by name.
const TEMPLATES: [(&str, &str); 5] = [
    ("program.system.j2", include_str!("../../../prompts/program.system.j2")),
    ("program.user.j2", include_str!("../../../prompts/program.user.j2")),
    ("relational_parse.system.j2", include_str!("../../../prompts/relational_parse.system.j2")),
    ("relational_parse.user.j2", include_str!("../../../prompts/relational_parse.user.j2")),
    ("repair.j2", include_str!("../../../prompts/repair.j2")),
];

/// A template that does not render.
#[derive(Debug, thiserror::Error)]
#[error("prompt template {name}: {message}")]
pub struct PromptError {
    /// The template.
    pub name: String,
    /// minijinja's message.
    pub message: String,
}

/// The compiled templates.
pub struct Prompts {
    env: Environment<'static>,
}

impl Prompts {
    /// Compiles every template.
    pub fn new() -> Result<Self, PromptError> {
        let mut env = Environment::new();
        env.set_undefined_behavior(UndefinedBehavior::Strict);
        let syntax = SyntaxConfig::builder().trim_blocks(true).lstrip_blocks(true).build();
        env.set_syntax(
            syntax.map_err(|error| PromptError { name: "(syntax)".to_owned(), message: error.to_string() })?,
        );
        for (name, source) in TEMPLATES {
            env.add_template(name, source)
                .map_err(|error| PromptError { name: name.to_owned(), message: error.to_string() })?;
        }
        Ok(Prompts { env })
    }

    /// Renders template `name` with `context`.
    pub fn render(&self, name: &str, context: impl Serialize) -> Result<String, PromptError> {
        let failed = |error: minijinja::Error| PromptError { name: name.to_owned(), message: format!("{error:#}") };
        let template = self.env.get_template(name).map_err(failed)?;
        template.render(Serde(context)).map_err(failed)
    }

    /// The repair message: the problems of the last reply and the request to answer again.
    pub fn repair(&self, problems: &[String]) -> Result<String, PromptError> {
        self.render("repair.j2", serde_json::json!({ "problems": problems }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn templates_compile_and_missing_variables_are_errors() {
        let prompts = Prompts::new().unwrap();
        let repair = prompts.repair(&["frames: 0 is outside [1, 10000]".to_owned()]).unwrap();
        assert!(repair.contains("- frames: 0 is outside [1, 10000]"), "{repair}");
        let error = prompts.render("program.user.j2", serde_json::json!({})).unwrap_err();
        assert!(error.to_string().contains("program.user.j2") && error.to_string().contains("undefined"), "{error}");
    }
}
