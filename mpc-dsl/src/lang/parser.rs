//! Recursive-descent parser that elaborates `.mpc` statements into an [`OcpBuilder`].

use std::collections::HashMap;

use crate::graph::{Expr, Graph};
use crate::linalg::{Matrix, Vector};
use crate::ocp::{Collocation, Decl, Integrator, OcpBuilder, OcpError, ParamKind, Slack, Stage};

mod soft;

use super::lexer::{Span, Tok, lex};
use super::value::{MAX_DIM, Val, call, mul, zip};
use super::{Diagnostic, DiagnosticKind, Diagnostics, ParseOptions, Parsed, Place, SourceMap};

/// Deepest expression nesting accepted (keeps hostile input from overflowing the stack).
const MAX_DEPTH: usize = 128;
/// Parsing stops after this many errors.
const MAX_ERRORS: usize = 50;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Role {
    State,
    Control,
    Param,
}

#[derive(Clone, Debug)]
enum Binding<'g> {
    Var(Role, Val<'g>),
    Let(Val<'g>),
}

type PResult<T> = Result<T, Box<Diagnostic>>;

struct Parser<'s, 'g> {
    src_len: usize,
    toks: Vec<(Tok<'s>, Span)>,
    pos: usize,
    g: &'g Graph,
    b: OcpBuilder<'g>,
    names: HashMap<String, (Binding<'g>, Span)>,
    /// Where validation items come from: item name -> span.
    spans: HashMap<String, Span>,
    /// Where the problem's items are written, for checks after parsing.
    source: SourceMap,
    diags: Vec<Diagnostic>,
    depth: usize,
    options: &'s ParseOptions,
    model: Option<(String, Span)>,
    horizon: Option<Span>,
    dynamics: Option<Span>,
    /// Where `solver { shift = ...; }` set the shift (a second one is an error).
    shift: Option<Span>,
    state_order: Vec<String>,
    variant_found: bool,
    pending_variant: Option<(usize, f64)>,
    nx: usize,
    nu: usize,
}

fn syntax(span: Span, msg: impl Into<String>) -> Box<Diagnostic> {
    Box::new(Diagnostic::new(DiagnosticKind::Syntax, span, msg))
}

fn semantic(span: Span, msg: impl Into<String>) -> Box<Diagnostic> {
    Box::new(Diagnostic::new(DiagnosticKind::Semantic, span, msg))
}

fn name_err(span: Span, msg: impl Into<String>) -> Box<Diagnostic> {
    Box::new(Diagnostic::new(DiagnosticKind::Name, span, msg))
}

pub(super) fn parse<'g>(
    g: &'g Graph,
    src: &str,
    options: &ParseOptions,
) -> Result<Parsed<'g>, Diagnostics> {
    let (toks, bad) = lex(src);
    let mut p = Parser {
        src_len: src.len(),
        toks,
        pos: 0,
        g,
        b: OcpBuilder::new(g, "model"),
        names: HashMap::new(),
        spans: HashMap::new(),
        source: SourceMap::default(),
        diags: bad
            .into_iter()
            .map(|s| {
                let text = src.get(s.clone()).unwrap_or("?").to_owned();
                let mut d = syntax(s, format!("unexpected character `{text}`"));
                d.label = "not part of the language".into();
                *d
            })
            .collect(),
        depth: 0,
        options,
        model: None,
        horizon: None,
        dynamics: None,
        shift: None,
        state_order: Vec::new(),
        variant_found: false,
        pending_variant: None,
        nx: 0,
        nu: 0,
    };
    p.file();
    p.finish()
}

impl<'s, 'g> Parser<'s, 'g> {
    // ---------------------------------------------------------------- token helpers

    fn peek(&self) -> Option<&Tok<'s>> {
        self.toks.get(self.pos).map(|(t, _)| t)
    }

    fn peek_at(&self, k: usize) -> Option<&Tok<'s>> {
        self.toks.get(self.pos + k).map(|(t, _)| t)
    }

    fn span(&self) -> Span {
        match self.toks.get(self.pos) {
            Some((_, s)) => s.clone(),
            None => self.src_len..self.src_len,
        }
    }

    fn prev_end(&self) -> usize {
        if self.pos == 0 {
            0
        } else {
            self.toks
                .get(self.pos - 1)
                .map_or(self.src_len, |(_, s)| s.end)
        }
    }

    fn bump(&mut self) -> Option<(Tok<'s>, Span)> {
        let t = self.toks.get(self.pos).cloned();
        if t.is_some() {
            self.pos += 1;
        }
        t
    }

    fn found(&self) -> String {
        self.peek()
            .map_or_else(|| "the end of the file".into(), ToString::to_string)
    }

    fn expect(&mut self, t: &Tok<'_>, what: &str) -> PResult<Span> {
        if self.peek() == Some(t) {
            Ok(self.bump().map(|(_, s)| s).unwrap_or_default())
        } else {
            let mut d = syntax(
                self.span(),
                format!("expected {what}, found {}", self.found()),
            );
            d.label = format!("expected {what}");
            Err(d)
        }
    }

    fn is_kw(&self, kw: &str) -> bool {
        matches!(self.peek(), Some(Tok::Ident(s)) if *s == kw)
    }

    fn eat_kw(&mut self, kw: &str) -> bool {
        if self.is_kw(kw) {
            self.pos += 1;
            true
        } else {
            false
        }
    }

    fn expect_kw(&mut self, kw: &str) -> PResult<Span> {
        if self.is_kw(kw) {
            Ok(self.bump().map(|(_, s)| s).unwrap_or_default())
        } else {
            let mut d = syntax(
                self.span(),
                format!("expected `{kw}`, found {}", self.found()),
            );
            d.label = format!("expected `{kw}`");
            Err(d)
        }
    }

    fn ident(&mut self, what: &str) -> PResult<(String, Span)> {
        match self.peek() {
            Some(Tok::Ident(s)) => {
                let s = (*s).to_owned();
                let span = self.span();
                self.pos += 1;
                Ok((s, span))
            }
            _ => {
                let mut d = syntax(
                    self.span(),
                    format!("expected {what}, found {}", self.found()),
                );
                d.label = format!("expected {what}");
                Err(d)
            }
        }
    }

    fn string(&mut self) -> PResult<String> {
        match self.peek() {
            Some(Tok::Str(s)) => {
                let s = (*s).to_owned();
                self.pos += 1;
                Ok(s)
            }
            _ => Err(syntax(
                self.span(),
                format!("expected a string in double quotes, found {}", self.found()),
            )),
        }
    }

    /// Skips to the end of the current statement: past the next `;` at this nesting level,
    /// or past the `}` that closes a block opened in this statement, or up to a `}` that
    /// closes the enclosing block.
    fn recover(&mut self) {
        let mut depth = 0usize;
        while let Some(t) = self.peek() {
            match t {
                Tok::Semi if depth == 0 => {
                    self.pos += 1;
                    return;
                }
                Tok::LBrace => depth += 1,
                Tok::RBrace => {
                    if depth == 0 {
                        return;
                    }
                    depth -= 1;
                    if depth == 0 {
                        self.pos += 1;
                        return;
                    }
                }
                _ => {}
            }
            self.pos += 1;
        }
    }

    fn error(&mut self, d: Diagnostic) {
        self.diags.push(d);
    }

    fn too_many(&self) -> bool {
        self.diags.len() >= MAX_ERRORS
    }

    // ---------------------------------------------------------------- statements

    fn file(&mut self) {
        while self.peek().is_some() && !self.too_many() {
            let start = self.pos;
            if let Err(d) = self.item() {
                self.error(*d);
                self.recover();
            }
            if self.pos == start {
                // A stray `}` (or anything the recovery could not skip): drop it.
                let s = self.span();
                self.error(*syntax(s, format!("unexpected {}", self.found())));
                self.pos += 1;
            }
        }
    }

    fn item(&mut self) -> PResult<()> {
        let span = self.span();
        let (kw, _) = self.ident("a statement (model, state, control, param, let, dynamics, horizon, cost, constraints, solver, variant)")?;
        match kw.as_str() {
            "model" => {
                let (name, nspan) = self.ident("the model name")?;
                self.expect(&Tok::Semi, "`;`")?;
                if self.model.is_some() {
                    return Err(name_err(nspan, "the model name is given twice"));
                }
                self.source.insert(Place::Model, nspan.clone());
                self.model = Some((name, nspan));
                Ok(())
            }
            "state" => self.declaration(Role::State, span),
            "control" => self.declaration(Role::Control, span),
            "param" => self.declaration(Role::Param, span),
            "let" => self.let_stmt(),
            "dynamics" => self.dynamics(span),
            "horizon" => {
                let (n, dt) = self.horizon_body()?;
                if self.horizon.is_some() {
                    return Err(name_err(span, "the horizon is given twice"));
                }
                self.horizon = Some(span.start..self.prev_end());
                self.b.horizon(n, dt);
                Ok(())
            }
            "variant" => self.variant(),
            "cost" => self.block(Self::cost_item),
            "constraints" => self.block(Self::constraint_item),
            "solver" => self.block(Self::solver_item),
            other => {
                let mut d = syntax(
                    span,
                    format!(
                        "unknown statement `{other}`: expected model, state, control, param, \
                         let, dynamics, horizon, cost, constraints, solver or variant"
                    ),
                );
                d.label = "unknown statement".into();
                Err(d)
            }
        }
    }

    fn block(&mut self, mut f: impl FnMut(&mut Self) -> PResult<()>) -> PResult<()> {
        self.expect(&Tok::LBrace, "`{`")?;
        while self.peek().is_some() && self.peek() != Some(&Tok::RBrace) && !self.too_many() {
            let start = self.pos;
            if let Err(d) = f(self) {
                self.error(*d);
                self.recover();
            }
            if self.pos == start {
                self.pos += 1;
            }
        }
        self.expect(&Tok::RBrace, "`}` closing the block")?;
        Ok(())
    }

    /// The options of `irk`: nothing, or `(name = value, ...)` with the counts `stages`,
    /// `steps` and `newton` and `collocation = gauss_legendre | radau_iia`, each at most
    /// once, in any order (defaults 2, 1, 3, Gauss-Legendre). The counts' ranges are checked
    /// by validation, located at the integrator.
    fn irk_options(&mut self) -> PResult<Integrator> {
        let (mut stages, mut steps, mut newton) = (None, None, None);
        let mut collocation = None;
        if self.peek() == Some(&Tok::LParen) {
            self.pos += 1;
            loop {
                let (key, kspan) = self.ident("`stages`, `steps`, `newton` or `collocation`")?;
                let given = match key.as_str() {
                    "stages" => stages.is_some(),
                    "steps" => steps.is_some(),
                    "newton" => newton.is_some(),
                    "collocation" => collocation.is_some(),
                    other => {
                        return Err(syntax(
                            kspan,
                            format!(
                                "unknown irk option `{other}`: the options are `stages`, \
                                 `steps`, `newton` and `collocation`"
                            ),
                        ));
                    }
                };
                if given {
                    return Err(semantic(kspan, format!("irk option `{key}` given twice")));
                }
                self.expect(&Tok::Eq, "`=`")?;
                match key.as_str() {
                    "collocation" => collocation = Some(self.collocation()?),
                    "stages" => stages = Some(self.count("irk `stages`")?),
                    "steps" => steps = Some(self.count("irk `steps`")?),
                    _ => newton = Some(self.count("irk `newton`")?),
                }
                if self.peek() != Some(&Tok::Comma) {
                    break;
                }
                self.pos += 1;
            }
            self.expect(&Tok::RParen, "`)`")?;
        }
        Ok(Integrator::Irk {
            stages: stages.unwrap_or(2),
            steps: steps.unwrap_or(1),
            newton: newton.unwrap_or(3),
            collocation: collocation.unwrap_or_default(),
        })
    }

    /// `gauss_legendre` or `radau_iia`.
    fn collocation(&mut self) -> PResult<Collocation> {
        let (name, span) = self.ident("`gauss_legendre` or `radau_iia`")?;
        match name.as_str() {
            "gauss_legendre" => Ok(Collocation::GaussLegendre),
            "radau_iia" => Ok(Collocation::RadauIia),
            other => Err(syntax(
                span,
                format!("unknown collocation `{other}`: use `gauss_legendre` or `radau_iia`"),
            )),
        }
    }

    fn count(&mut self, what: &str) -> PResult<usize> {
        let (v, span) = self.const_scalar(what)?;
        if v.fract() != 0.0 || !(0.0..=MAX_DIM as f64).contains(&v) {
            return Err(semantic(
                span,
                format!("{what} must be a whole number between 0 and {MAX_DIM}, found {v}"),
            ));
        }
        Ok(v as usize)
    }

    fn declaration(&mut self, role: Role, start: Span) -> PResult<()> {
        let (name, nspan) = self.ident("a name")?;
        let mut decl = if self.peek() == Some(&Tok::LBracket) {
            self.pos += 1;
            let n = self.count("the length")?;
            self.expect(&Tok::RBracket, "`]`")?;
            Decl::vector(&name, n)
        } else {
            Decl::scalar(&name)
        };
        let mut kind = None;
        let mut start_vals: Option<(Vec<f64>, Span)> = None;
        loop {
            if self.eat_kw("unit") {
                let s = self.string()?;
                decl = decl.unit(&s);
            } else if self.eat_kw("doc") {
                let s = self.string()?;
                decl = decl.describe(&s);
            } else if role == Role::Param && self.eat_kw("stage") {
                kind = Some(ParamKind::Stage);
            } else if role == Role::Param && self.eat_kw("global") {
                kind = Some(ParamKind::Global);
            } else if (role == Role::Param && self.eat_kw("default"))
                || (role != Role::Param && self.eat_kw("guess"))
            {
                start_vals = Some(self.const_values("the starting value")?);
            } else {
                break;
            }
        }
        self.expect(
            &Tok::Semi,
            "`;` (or unit, doc, guess, default, stage, global)",
        )?;
        if let Some((v, _)) = &start_vals {
            decl = decl.start(v);
        }
        if self.names.contains_key(&name) {
            let mut d = name_err(
                nspan,
                format!("duplicate name `{name}`: it is declared twice"),
            );
            d.label = "declared again here".into();
            return Err(d);
        }
        let syms = match role {
            Role::State => {
                self.state_order.push(name.clone());
                let s = self.b.state(decl);
                self.nx += s.len();
                s
            }
            Role::Control => {
                let s = self.b.control(decl);
                self.nu += s.len();
                s
            }
            Role::Param => {
                let Some(kind) = kind else {
                    return Err(syntax(
                        nspan,
                        format!(
                            "parameter `{name}`: say `stage` (one value per stage) or `global`"
                        ),
                    ));
                };
                self.b.param(decl, kind)
            }
        };
        let scalar = self.peek_scalar_decl(&syms, &name);
        let val = if scalar {
            Val::S(syms[0])
        } else {
            Val::V(syms)
        };
        let decl_span = start.start..self.prev_end();
        self.spans.insert(name.clone(), nspan.clone());
        self.source
            .insert(Place::Declaration(name.clone()), nspan.clone());
        let what = if role == Role::Param {
            "default value of"
        } else {
            "initial guess of"
        };
        if let Some((_, s)) = start_vals {
            self.spans.insert(format!("{what} `{name}`"), s);
        }
        self.names
            .insert(name, (Binding::Var(role, val), decl_span));
        Ok(())
    }

    fn peek_scalar_decl(&self, syms: &Vector<'g>, name: &str) -> bool {
        syms.len() == 1 && syms[0].symbol_name().as_deref() == Some(name)
    }

    fn let_stmt(&mut self) -> PResult<()> {
        let (name, nspan) = self.ident("a name")?;
        self.expect(&Tok::Eq, "`=`")?;
        let (v, _) = self.expr()?;
        self.expect(&Tok::Semi, "`;`")?;
        if self.names.contains_key(&name) || is_reserved(&name) {
            return Err(name_err(
                nspan,
                format!("duplicate name `{name}`: it is already defined"),
            ));
        }
        self.names.insert(name, (Binding::Let(v), nspan));
        Ok(())
    }

    fn horizon_body(&mut self) -> PResult<(usize, f64)> {
        self.expect_kw("N")?;
        self.expect(&Tok::Eq, "`=`")?;
        let n = self.count("N")?;
        self.expect(&Tok::Comma, "`,`")?;
        self.expect_kw("dt")?;
        self.expect(&Tok::Eq, "`=`")?;
        let (dt, _) = self.const_scalar("dt")?;
        self.expect(&Tok::Semi, "`;`")?;
        Ok((n, dt))
    }

    /// One setting of a `solver { ... }` block: `shift = on;` or `shift = off;`.
    fn solver_item(&mut self) -> PResult<()> {
        let (key, kspan) = self.ident("a solver setting (shift)")?;
        if key != "shift" {
            return Err(syntax(
                kspan,
                format!("unknown solver setting `{key}`: expected `shift = on;` or `shift = off;`"),
            ));
        }
        self.expect(&Tok::Eq, "`=`")?;
        let (value, vspan) = self.ident("`on` or `off`")?;
        let on = match value.as_str() {
            "on" => true,
            "off" => false,
            _ => {
                return Err(syntax(
                    vspan,
                    format!("`shift` is `on` or `off`, not `{value}`"),
                ));
            }
        };
        self.expect(&Tok::Semi, "`;`")?;
        if self.shift.is_some() {
            return Err(name_err(kspan, "the shift is given twice"));
        }
        self.shift = Some(kspan);
        self.b.shift(on);
        Ok(())
    }

    fn variant(&mut self) -> PResult<()> {
        let (name, _) = self.ident("the variant name")?;
        self.expect(&Tok::LBrace, "`{`")?;
        let hspan = self.expect_kw("horizon")?;
        let (n, dt) = self.horizon_body()?;
        self.expect(&Tok::RBrace, "`}` (a variant holds one horizon statement)")?;
        if self.options.variant.as_deref() == Some(name.as_str()) {
            self.variant_found = true;
            self.horizon = Some(hspan.start..self.prev_end());
            // Applied at the end, so it wins over the default horizon in any order.
            self.spans.insert("variant horizon".into(), hspan);
            self.pending_variant = Some((n, dt));
        }
        Ok(())
    }

    fn dynamics(&mut self, start: Span) -> PResult<()> {
        let kind_span = self.span();
        let (kind, _) = self.ident("`ode` or `discrete`")?;
        let discrete = match kind.as_str() {
            "ode" => false,
            "discrete" => true,
            _ => {
                return Err(syntax(
                    kind_span,
                    format!("expected `ode` or `discrete`, found `{kind}`"),
                ));
            }
        };
        let integrator = if discrete {
            Integrator::Rk4 { steps: 1 }
        } else {
            self.integrator()?
        };
        let head = start.start..self.prev_end();
        let eq_kw = if discrete { "next" } else { "der" };
        let mut eqs: HashMap<String, (Vec<Expr<'g>>, Span)> = HashMap::new();
        let mut eq_spans = Vec::new();
        let errors_before = self.diags.len();
        self.block(|p| {
            p.expect_kw(eq_kw)?;
            p.expect(&Tok::LParen, "`(`")?;
            let (name, nspan) = p.ident("a state name")?;
            p.expect(&Tok::RParen, "`)`")?;
            p.expect(&Tok::Eq, "`=`")?;
            let (v, vspan) = p.expr()?;
            p.expect(&Tok::Semi, "`;`")?;
            let Some((Binding::Var(Role::State, sv), _)) = p.names.get(&name) else {
                return Err(name_err(nspan, format!("`{name}` is not a declared state")));
            };
            let n = sv.entries().map_or(0, |e| e.len());
            let Some(entries) = v.entries().filter(|e| e.len() == n) else {
                return Err(semantic(
                    vspan,
                    format!(
                        "{eq_kw}({name}) is {} but the state `{name}` has {n} entries",
                        v.shape()
                    ),
                ));
            };
            if eqs.contains_key(&name) {
                return Err(name_err(nspan, format!("{eq_kw}({name}) is given twice")));
            }
            eq_spans.push((Place::Equation(name.clone()), vspan));
            eqs.insert(name, (entries, nspan));
            Ok(())
        })?;
        for (place, span) in eq_spans {
            self.source.insert(place, span);
        }
        if self.dynamics.is_some() {
            return Err(name_err(head, "the dynamics are given twice"));
        }
        self.dynamics = Some(head.clone());
        self.spans.insert("the dynamics".into(), head.clone());
        let mut all = Vec::new();
        let mut missing = Vec::new();
        for s in &self.state_order {
            match eqs.get(s) {
                Some((e, _)) => all.extend_from_slice(e),
                None => missing.push(s.clone()),
            }
        }
        if !missing.is_empty() && self.diags.len() == errors_before {
            return Err(name_err(
                head,
                format!(
                    "the dynamics give no equation for state(s) {}: add `{eq_kw}(NAME) = ...;`",
                    missing
                        .iter()
                        .map(|m| format!("`{m}`"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            ));
        }
        if discrete {
            self.b.discrete(&all);
        } else {
            self.b.ode(&all, integrator);
        }
        Ok(())
    }

    /// `rk4`, `rk4(k)`, `euler` or `irk(...)`, after `dynamics ode`; its span is kept for
    /// the validation's errors.
    fn integrator(&mut self) -> PResult<Integrator> {
        let ispan = self.span();
        let (name, _) = self.ident("an integrator (`rk4`, `euler` or `irk`)")?;
        let integrator = match name.as_str() {
            "rk4" => {
                let mut steps = 1;
                if self.peek() == Some(&Tok::LParen) {
                    self.pos += 1;
                    steps = self.count("the number of RK4 substeps")?;
                    self.expect(&Tok::RParen, "`)`")?;
                }
                Integrator::Rk4 { steps }
            }
            "euler" => Integrator::Euler,
            "irk" => self.irk_options()?,
            other => {
                return Err(syntax(
                    ispan,
                    format!(
                        "unknown integrator `{other}`: use `rk4`, `rk4(k)`, `euler` or \
                         `irk(stages = s, steps = k, newton = n)`"
                    ),
                ));
            }
        };
        self.spans
            .insert("integrator".into(), ispan.start..self.prev_end());
        Ok(integrator)
    }

    fn weight(&mut self) -> PResult<(Matrix<'g>, Span)> {
        let (v, span) = self.expr()?;
        match v {
            Val::M(m) => Ok((m, span)),
            other => Err(semantic(
                span,
                format!(
                    "a weight must be a matrix, found {}: write diag(...), eye(n) or mat(...)",
                    other.shape()
                ),
            )),
        }
    }

    fn vector_expr(&mut self) -> PResult<(Vec<Expr<'g>>, Span)> {
        let (v, span) = self.expr()?;
        match v.entries() {
            Some(e) => Ok((e, span)),
            None => Err(semantic(
                span,
                format!("expected a vector, found {}", v.shape()),
            )),
        }
    }

    fn cost_item(&mut self) -> PResult<()> {
        let start = self.span();
        let (kw, kspan) = self.ident("Q, R, P, residual, terminal, stage or rate")?;
        // `stage NAME = l;`, `terminal NAME = l;` (but `terminal residual NAME = ...`).
        let general = match kw.as_str() {
            "stage" => true,
            "terminal" => !(self.is_kw("residual") && self.peek_at(1) != Some(&Tok::Eq)),
            _ => false,
        };
        if general {
            let stage = if kw == "stage" {
                Stage::Path
            } else {
                Stage::Terminal
            };
            return self.general_cost(stage);
        }
        match kw.as_str() {
            "Q" | "R" | "P" => {
                self.expect(&Tok::Eq, "`=`")?;
                let (w, wspan) = self.weight()?;
                self.source.insert(Place::Weight(kw.clone()), wspan);
                let n = if kw == "R" { self.nu } else { self.nx };
                let reference = if self.eat_kw("ref") {
                    let (r, rspan) = self.vector_expr()?;
                    self.source
                        .insert(Place::Reference(kw.clone()), rspan.clone());
                    self.spans.insert(format!("reference of {kw}"), rspan);
                    r
                } else {
                    Vector::zeros(self.g, n).to_vec()
                };
                self.expect(&Tok::Semi, "`;` (or `ref`)")?;
                let span = start.start..self.prev_end();
                if self.spans.insert(kw.clone(), span).is_some() {
                    return Err(name_err(kspan, format!("{kw} is given twice")));
                }
                match kw.as_str() {
                    "Q" => self.b.state_cost(w, &reference),
                    "R" => self.b.control_cost(w, &reference),
                    _ => self.b.terminal_cost(w, &reference),
                };
                Ok(())
            }
            "residual" | "terminal" => {
                let stage = if kw == "terminal" {
                    self.expect_kw("residual")?;
                    Stage::Terminal
                } else {
                    Stage::Path
                };
                let (name, nspan) = self.ident("the residual's name")?;
                self.expect(&Tok::Eq, "`=`")?;
                let (r, rspan) = self.vector_expr()?;
                self.expect_kw("weight")?;
                let (w, wspan) = self.weight()?;
                self.expect(&Tok::Semi, "`;`")?;
                self.source.insert(Place::Residual(name.clone()), rspan);
                self.source
                    .insert(Place::ResidualWeight(name.clone()), wspan.clone());
                self.spans.insert(format!("residual `{name}`"), nspan);
                self.spans
                    .insert(format!("weight of residual `{name}`"), wspan);
                self.b.residual(&name, stage, &r, w);
                Ok(())
            }
            "rate" => {
                self.expect(&Tok::Eq, "`=`")?;
                let (w, wspan) = self.weight()?;
                self.expect_kw("prev")?;
                let (prev, pspan) = self.vector_expr()?;
                self.expect(&Tok::Semi, "`;`")?;
                self.source
                    .insert(Place::Weight("rate".into()), wspan.clone());
                self.source
                    .insert(Place::Reference("rate".into()), pspan.clone());
                self.spans.insert("input-rate weight".into(), wspan);
                self.spans
                    .insert("previous control of the input-rate cost".into(), pspan);
                self.b.input_rate(w, &prev);
                Ok(())
            }
            other => Err(syntax(
                kspan,
                format!(
                    "unknown cost term `{other}`: expected Q, R, P, residual, terminal residual, \
                     stage NAME = ..., terminal NAME = ... or rate"
                ),
            )),
        }
    }

    /// The rest of a general cost term, `NAME = l;` after `stage` or `terminal`: `l` a
    /// scalar expression added to the objective as it is.
    fn general_cost(&mut self, stage: Stage) -> PResult<()> {
        let (name, nspan) = self.ident("the cost term's name")?;
        self.expect(&Tok::Eq, "`=`")?;
        let (v, vspan) = self.expr()?;
        let Val::S(l) = v else {
            return Err(semantic(
                vspan,
                format!(
                    "a general cost term must be a scalar, found {}: sum a vector's entries \
                     (sum(...), dot(...), norm2(...)) or use `residual` for least squares",
                    v.shape()
                ),
            ));
        };
        self.expect(&Tok::Semi, "`;`")?;
        self.source.insert(Place::GeneralCost(name.clone()), vspan);
        if self
            .spans
            .insert(format!("cost term `{name}`"), nspan.clone())
            .is_some()
        {
            return Err(name_err(
                nspan,
                format!("cost term `{name}` is given twice"),
            ));
        }
        self.b.general_cost(&name, stage, l);
        Ok(())
    }

    fn constraint_item(&mut self) -> PResult<()> {
        let general = self.is_kw("terminal") || self.peek_at(1) == Some(&Tok::Colon);
        if general {
            return self.general_constraint();
        }
        let start = self.span();
        let (name, nspan) =
            self.ident("a state or control to bound, or `NAME:` for a constraint")?;
        let Some((Binding::Var(role, v), _)) = self.names.get(&name).cloned() else {
            return Err(name_err(
                nspan,
                format!("`{name}` is not a declared state or control (box bounds apply to those)"),
            ));
        };
        if role == Role::Param {
            return Err(name_err(
                nspan,
                format!("`{name}` is a parameter; box bounds apply to states and controls"),
            ));
        }
        let mut syms = v.entries().unwrap_or_default();
        if self.peek() == Some(&Tok::LBracket) {
            self.pos += 1;
            let (lo, hi) = self.index_range(syms.len())?;
            self.expect(&Tok::RBracket, "`]`")?;
            syms = syms[lo..hi].to_vec();
        }
        self.expect_kw("in")?;
        self.expect(&Tok::LBracket, "`[` starting `[lower, upper]`")?;
        let (lo, lspan) = self.const_values("the lower bound")?;
        self.expect(&Tok::Comma, "`,`")?;
        let (hi, hspan) = self.const_values("the upper bound")?;
        self.expect(&Tok::RBracket, "`]`")?;
        let soft = if self.eat_kw("soft") {
            Some(self.box_soft(&name, syms.len())?)
        } else {
            None
        };
        self.expect(&Tok::Semi, "`;` (or `soft`)")?;
        let n = syms.len();
        let fit = |v: Vec<f64>, span: Span| -> PResult<Vec<f64>> {
            match v.len() {
                1 => Ok(vec![v[0]; n]),
                k if k == n => Ok(v),
                k => Err(semantic(
                    span,
                    format!("the bound has {k} entries but `{name}` selects {n}"),
                )),
            }
        };
        let lo = fit(lo, lspan)?;
        let hi = fit(hi, hspan)?;
        let span = start.start..self.prev_end();
        let what = if role == Role::State {
            "state bound"
        } else {
            "control bound"
        };
        for s in &syms {
            self.spans.insert(format!("{what} on `{s}`"), span.clone());
            self.spans
                .insert(format!("{what} on `{s}` (lower)"), span.clone());
            self.spans
                .insert(format!("{what} on `{s}` (upper)"), span.clone());
            if soft.is_some() {
                self.spans
                    .insert(format!("soft {what} on `{s}`"), span.clone());
                (self.spans).insert(
                    format!("slack penalty of soft {what} on `{s}`"),
                    span.clone(),
                );
            }
        }
        match soft {
            Some(slacks) => self.b.soft_bound_each(&syms, &lo, &hi, &slacks),
            None => self.b.bound_each(&syms, &lo, &hi),
        };
        Ok(())
    }

    fn general_constraint(&mut self) -> PResult<()> {
        let stage = if self.eat_kw("terminal") {
            Stage::Terminal
        } else {
            Stage::Path
        };
        let (name, nspan) = self.ident("the constraint's name")?;
        self.expect(&Tok::Colon, "`:`")?;
        let (lo, lspan) = self.const_values("the lower bound")?;
        self.expect(&Tok::Le, "`<=`")?;
        let (h, hspan) = self.vector_expr()?;
        self.expect(&Tok::Le, "`<=`")?;
        let (hi, uspan) = self.const_values("the upper bound")?;
        let mut soft = None;
        if self.eat_kw("soft") {
            let mut s = Slack { l1: 0.0, l2: 0.0 };
            loop {
                if self.eat_kw("l1") {
                    self.expect(&Tok::Eq, "`=`")?;
                    s.l1 = self.const_scalar("the L1 penalty")?.0;
                } else if self.eat_kw("l2") {
                    self.expect(&Tok::Eq, "`=`")?;
                    s.l2 = self.const_scalar("the L2 penalty")?.0;
                } else {
                    return Err(syntax(
                        self.span(),
                        format!("expected `l1 = ...` or `l2 = ...`, found {}", self.found()),
                    ));
                }
                if self.peek() != Some(&Tok::Comma) {
                    break;
                }
                self.pos += 1;
            }
            soft = Some(s);
        }
        self.expect(&Tok::Semi, "`;` (or `soft`)")?;
        let n = h.len();
        for (v, span) in [(&lo, &lspan), (&hi, &uspan)] {
            if v.len() != 1 && v.len() != n {
                return Err(semantic(
                    span.clone(),
                    format!(
                        "the bound has {} entries but the constraint `{name}` has {n}",
                        v.len()
                    ),
                ));
            }
        }
        let item = format!("constraint `{name}`");
        self.source
            .insert(Place::Constraint(name.clone()), hspan.clone());
        self.spans.insert(item.clone(), nspan.clone());
        for i in 0..n {
            self.spans
                .insert(format!("{item} entry {i}"), hspan.clone());
        }
        self.spans.insert(format!("slack penalty of {item}"), nspan);
        match soft {
            Some(s) => self.b.soft_constraint(&name, stage, &h, &lo, &hi, s),
            None => self.b.constraint(&name, stage, &h, &lo, &hi),
        };
        Ok(())
    }

    /// `i` or `i:j` inside brackets; returns a half-open range within `0..len`.
    fn index_range(&mut self, len: usize) -> PResult<(usize, usize)> {
        let (a, aspan) = self.const_scalar("an index")?;
        let check = |v: f64, span: Span, max: usize| -> PResult<usize> {
            if v.fract() == 0.0 && v >= 0.0 && v <= max as f64 {
                Ok(v as usize)
            } else {
                Err(semantic(
                    span,
                    format!("index {v} is out of range: it must be a whole number in 0..{max}"),
                ))
            }
        };
        if self.peek() == Some(&Tok::Colon) {
            self.pos += 1;
            let (b, bspan) = self.const_scalar("an index")?;
            let a = check(a, aspan.clone(), len)?;
            let b = check(b, bspan, len)?;
            if a >= b {
                return Err(semantic(aspan, format!("empty slice {a}:{b}")));
            }
            Ok((a, b))
        } else {
            let a = check(a, aspan, len.saturating_sub(1))?;
            if len == 0 {
                return Err(semantic(self.span(), "cannot index an empty vector"));
            }
            Ok((a, a + 1))
        }
    }

    // ---------------------------------------------------------------- constants

    fn const_values(&mut self, what: &str) -> PResult<(Vec<f64>, Span)> {
        let (v, span) = self.expr()?;
        let entries = v.entries().ok_or_else(|| {
            semantic(
                span.clone(),
                format!("{what} must be a number or a vector, found {}", v.shape()),
            )
        })?;
        let vals: Option<Vec<f64>> = entries.iter().map(Expr::as_constant).collect();
        match vals {
            Some(v) => Ok((v, span)),
            None => Err(semantic(
                span,
                format!(
                    "{what} must be a constant (numbers, `inf`, `pi` and constant `let`s only)"
                ),
            )),
        }
    }

    fn const_scalar(&mut self, what: &str) -> PResult<(f64, Span)> {
        let (v, span) = self.const_values(what)?;
        if v.len() == 1 {
            Ok((v[0], span))
        } else {
            Err(semantic(
                span,
                format!("{what} must be a single number, found {} values", v.len()),
            ))
        }
    }

    // ---------------------------------------------------------------- expressions

    fn expr(&mut self) -> PResult<(Val<'g>, Span)> {
        self.depth += 1;
        let r = if self.depth > MAX_DEPTH {
            Err(syntax(
                self.span(),
                format!("expression nested deeper than {MAX_DEPTH} levels"),
            ))
        } else {
            self.add()
        };
        self.depth -= 1;
        r
    }

    fn add(&mut self) -> PResult<(Val<'g>, Span)> {
        let (mut a, mut span) = self.mul()?;
        loop {
            let op = match self.peek() {
                Some(Tok::Plus) => "+",
                Some(Tok::Minus) => "-",
                _ => return Ok((a, span)),
            };
            let ospan = self.span();
            self.pos += 1;
            let (b, bspan) = self.mul()?;
            let r = if op == "+" {
                zip(op, &a, &b, |x, y| x + y)
            } else {
                zip(op, &a, &b, |x, y| x - y)
            };
            a = r.map_err(|m| {
                let mut d = semantic(ospan, m);
                d.label = "shapes do not fit".into();
                d
            })?;
            span = span.start..bspan.end;
            finite(&a, &span)?;
        }
    }

    fn mul(&mut self) -> PResult<(Val<'g>, Span)> {
        let (mut a, mut span) = self.unary()?;
        loop {
            let op = match self.peek() {
                Some(Tok::Star) => "*",
                Some(Tok::Slash) => "/",
                _ => return Ok((a, span)),
            };
            let ospan = self.span();
            self.pos += 1;
            let (b, bspan) = self.unary()?;
            let r = if op == "*" {
                mul(&a, &b)
            } else if matches!(b, Val::S(_)) {
                zip(op, &a, &b, |x, y| x / y)
            } else {
                Err(format!("`/` divides by a scalar only, found {}", b.shape()))
            };
            a = r.map_err(|m| semantic(ospan, m))?;
            span = span.start..bspan.end;
            finite(&a, &span)?;
        }
    }

    fn unary(&mut self) -> PResult<(Val<'g>, Span)> {
        if self.peek() == Some(&Tok::Minus) {
            let s = self.span();
            self.pos += 1;
            self.depth += 1;
            let r = if self.depth > MAX_DEPTH {
                Err(syntax(
                    s.clone(),
                    format!("expression nested deeper than {MAX_DEPTH} levels"),
                ))
            } else {
                self.unary()
            };
            self.depth -= 1;
            let (v, vspan) = r?;
            let zero = Val::S(self.g.zero());
            let neg = zip("-", &zero, &v, |x, y| x - y).map_err(|m| semantic(s.clone(), m))?;
            let span = s.start..vspan.end;
            finite(&neg, &span)?;
            return Ok((neg, span));
        }
        self.power()
    }

    fn power(&mut self) -> PResult<(Val<'g>, Span)> {
        let (a, span) = self.postfix()?;
        if self.peek() == Some(&Tok::Caret) {
            let ospan = self.span();
            self.pos += 1;
            self.depth += 1;
            let r = if self.depth > MAX_DEPTH {
                Err(syntax(
                    ospan.clone(),
                    format!("expression nested deeper than {MAX_DEPTH} levels"),
                ))
            } else {
                self.unary()
            };
            self.depth -= 1;
            let (b, bspan) = r?;
            if !matches!(b, Val::S(_)) || matches!(a, Val::M(_)) {
                return Err(semantic(
                    ospan,
                    format!(
                        "`^` raises a scalar or each vector entry to a scalar power, found {} ^ {}",
                        a.shape(),
                        b.shape()
                    ),
                ));
            }
            let v = zip("^", &a, &b, |x, y| x.pow(y)).map_err(|m| semantic(ospan, m))?;
            let span = span.start..bspan.end;
            finite(&v, &span)?;
            return Ok((v, span));
        }
        Ok((a, span))
    }

    fn postfix(&mut self) -> PResult<(Val<'g>, Span)> {
        let (mut v, mut span) = self.primary()?;
        while self.peek() == Some(&Tok::LBracket) {
            self.pos += 1;
            let entries = v
                .entries()
                .filter(|_| !matches!(v, Val::S(_)))
                .ok_or_else(|| {
                    semantic(
                        span.clone(),
                        format!("only vectors can be indexed, this is {}", v.shape()),
                    )
                })?;
            let (lo, hi) = self.index_range(entries.len())?;
            let end = self.expect(&Tok::RBracket, "`]`")?;
            v = if hi == lo + 1 {
                Val::S(entries[lo])
            } else {
                Val::V(entries[lo..hi].iter().copied().collect())
            };
            span = span.start..end.end;
        }
        Ok((v, span))
    }

    fn primary(&mut self) -> PResult<(Val<'g>, Span)> {
        let span = self.span();
        match self.peek().cloned() {
            Some(Tok::Num(x)) => {
                self.pos += 1;
                Ok((Val::S(self.g.constant_unchecked(x)), span))
            }
            Some(Tok::LParen) => {
                self.pos += 1;
                let (v, _) = self.expr()?;
                let end = self.expect(&Tok::RParen, "`)`")?;
                Ok((v, span.start..end.end))
            }
            Some(Tok::LBracket) => {
                // Vector literal: scalars and vectors, concatenated.
                self.pos += 1;
                let mut out = Vec::new();
                if self.peek() != Some(&Tok::RBracket) {
                    loop {
                        let (v, vspan) = self.expr()?;
                        match v.entries() {
                            Some(e) => out.extend(e),
                            None => {
                                return Err(semantic(
                                    vspan,
                                    "a matrix cannot be an entry of a vector literal",
                                ));
                            }
                        }
                        if out.len() > MAX_DIM {
                            return Err(semantic(vspan, format!("vector longer than {MAX_DIM}")));
                        }
                        if self.peek() != Some(&Tok::Comma) {
                            break;
                        }
                        self.pos += 1;
                    }
                }
                let end = self.expect(&Tok::RBracket, "`,` or `]`")?;
                if out.is_empty() {
                    return Err(semantic(span.start..end.end, "empty vector literal"));
                }
                Ok((Val::V(Vector::new(out)), span.start..end.end))
            }
            Some(Tok::Ident(name)) => {
                self.pos += 1;
                if self.peek() == Some(&Tok::LParen) {
                    self.pos += 1;
                    let mut args = Vec::new();
                    if self.peek() != Some(&Tok::RParen) {
                        loop {
                            args.push(self.expr()?.0);
                            if self.peek() != Some(&Tok::Comma) {
                                break;
                            }
                            self.pos += 1;
                        }
                    }
                    let end = self.expect(&Tok::RParen, "`,` or `)`")?;
                    let v = call(self.g, name, &args).map_err(|m| {
                        let mut d = semantic(span.clone(), m);
                        d.label = format!("in this call of `{name}`");
                        d
                    })?;
                    let span = span.start..end.end;
                    finite(&v, &span)?;
                    return Ok((v, span));
                }
                match name {
                    "pi" => {
                        return Ok((
                            Val::S(self.g.constant_unchecked(core::f64::consts::PI)),
                            span,
                        ));
                    }
                    "inf" => return Ok((Val::S(self.g.constant_unchecked(f64::INFINITY)), span)),
                    _ => {}
                }
                match self.names.get(name) {
                    Some((Binding::Var(_, v) | Binding::Let(v), _)) => Ok((v.clone(), span)),
                    None => {
                        let mut d = name_err(
                            span,
                            format!(
                                "unknown name `{name}`: declare it (state, control, param or let) before using it"
                            ),
                        );
                        d.label = "unknown name".into();
                        Err(d)
                    }
                }
            }
            _ => {
                let mut d = syntax(
                    span,
                    format!("expected an expression, found {}", self.found()),
                );
                d.label = "expected an expression".into();
                Err(d)
            }
        }
    }

    // ---------------------------------------------------------------- end

    fn finish(mut self) -> Result<Parsed<'g>, Diagnostics> {
        if let Some(v) = &self.options.variant
            && !self.variant_found
        {
            let d = name_err(
                0..0,
                format!("no `variant {v} {{ ... }}` block in this file"),
            );
            self.diags.push(*d);
        }
        if let Some((n, dt)) = self.pending_variant.take() {
            self.b.horizon(n, dt);
        }
        let mut name = match &self.model {
            Some((n, _)) => n.clone(),
            None => {
                self.diags.push(*syntax(
                    0..0,
                    "the file must name its model: add `model NAME;`",
                ));
                String::new()
            }
        };
        if let Some(v) = &self.options.variant {
            name = format!("{name}_{v}");
        }
        if self.dynamics.is_none() && self.diags.is_empty() {
            self.diags.push(*syntax(
                self.src_len..self.src_len,
                "no dynamics: add `dynamics ode rk4 { der(x) = ...; }`",
            ));
        }
        if self.horizon.is_none() && self.diags.is_empty() {
            self.diags.push(*syntax(
                self.src_len..self.src_len,
                "no horizon: add `horizon N = 20, dt = 0.05;`",
            ));
        }
        if !self.diags.is_empty() {
            self.diags.sort_by_key(|d| d.span.start);
            return Err(Diagnostics { items: self.diags });
        }
        let spans = std::mem::take(&mut self.spans);
        let locate = |item: Option<&str>| -> Span {
            let Some(item) = item else { return 0..0 };
            if let Some(s) = spans.get(item) {
                return s.clone();
            }
            // A backquoted declared name inside the item.
            if let Some(start) = item.find('`')
                && let Some(len) = item[start + 1..].find('`')
            {
                let inner = &item[start + 1..start + 1 + len];
                let base = inner.split('[').next().unwrap_or(inner);
                if let Some(s) = spans.get(base) {
                    return s.clone();
                }
            }
            0..0
        };
        let horizon_span = self.horizon.clone().unwrap_or(0..0);
        match self.b.build_with_warnings() {
            Ok((mut ocp, warnings)) => {
                ocp.name = name;
                let warnings = warnings
                    .into_iter()
                    .map(|w| {
                        let crate::ocp::OcpWarning::UnusedControl { name: n } = &w;
                        let span = locate(Some(&format!("`{n}`")));
                        let mut d = Diagnostic::new(
                            DiagnosticKind::Warning(w.clone()),
                            span,
                            w.to_string(),
                        );
                        d.label = "declared here".into();
                        d
                    })
                    .collect();
                Ok(Parsed {
                    ocp,
                    warnings,
                    source: self.source,
                })
            }
            Err(e) => {
                let mut items: Vec<Diagnostic> = e
                    .errors
                    .into_iter()
                    .map(|err| {
                        let span = match &err {
                            OcpError::ZeroHorizon | OcpError::NonPositiveDt { .. } => {
                                horizon_span.clone()
                            }
                            OcpError::ZeroSubsteps
                            | OcpError::IrkStages { .. }
                            | OcpError::IrkZero { .. } => locate(Some("integrator")),
                            OcpError::UnknownSymbol { item, .. } => locate(Some(item)),
                            other => locate(other.culprit()),
                        };
                        let mut d = Diagnostic::new(
                            DiagnosticKind::Validation(err.clone()),
                            span,
                            err.to_string(),
                        );
                        d.label = "the problem is here".into();
                        d
                    })
                    .collect();
                items.sort_by_key(|d| d.span.start);
                Err(Diagnostics { items })
            }
        }
    }
}

/// Refuses a value with an entry that is a non-finite constant expression (`0/0`, `1/0`,
/// `sqrt(-1)`, `log(0)`, overflow, `inf - inf`): the graph keeps such operations unfolded
/// (and NaN constants as they are), so each is caught at the innermost operation that made
/// it, which `span` covers. An infinite constant alone (`inf`, `-inf`, `2 * inf`) is a bound
/// and passes; validation refuses it inside a function.
fn finite(v: &Val<'_>, span: &Span) -> PResult<()> {
    let entries = match v {
        Val::S(e) => vec![*e],
        Val::V(x) => x.to_vec(),
        Val::M(m) => m.as_row_major().to_vec(),
    };
    let bad = entries
        .iter()
        .find(|e| e.is_non_finite_constant() && !e.as_constant().is_some_and(f64::is_infinite));
    let Some(value) = bad.and_then(Expr::constant_value) else {
        return Ok(());
    };
    let cause = if value.is_nan() {
        "0/0, 0 * inf, inf - inf, or sqrt, log, asin, acos or a fractional power of a number \
         outside their domain"
    } else {
        "a division by zero, log(0), a negative power of 0, or an overflow"
    };
    let mut d = semantic(
        span.clone(),
        format!(
            "this constant expression is not finite (it evaluates to {value}): {cause}; \
             fix the numbers so that it has a finite value"
        ),
    );
    d.label = format!("evaluates to {value}");
    Err(d)
}

fn is_reserved(name: &str) -> bool {
    matches!(name, "pi" | "inf")
}
