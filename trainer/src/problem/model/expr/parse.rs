//! The parser: expression text → [`Ast`] (a tree with the column of every node).
//!
//! Grammar (EBNF; blanks between tokens are ignored, columns count characters from 1):
//!
//! ```text
//! definition = name "=" expr ;
//! expr       = term { ("+" | "-") term } ;            (* left-associative *)
//! term       = unary { ("*" | "/") unary } ;          (* left-associative *)
//! unary      = "-" unary | power ;
//! power      = atom [ "^" unary ] ;                   (* right-associative: 2^3^2 = 2^9 *)
//! atom       = number | "pi" | name | call | "(" expr ")" ;
//! call       = function "(" expr { "," expr } ")" ;
//! function   = "sin" | "cos" | "tan" | "asin" | "acos" | "atan" | "atan2" | "exp" | "log"
//!            | "sqrt" | "sinh" | "cosh" | "tanh" | "abs" | "min" | "max" ;
//! number     = ( digits [ "." [ digits ] ] | "." digits ) [ ("e" | "E") [ "+" | "-" ] digits ] ;
//! name       = ( letter | "_" ) { letter | digit | "_" } ;   (* ASCII *)
//! ```
//!
//! So `^` binds tighter than a unary minus on its left (`-x^2 = -(x^2)`) and its exponent may
//! carry a sign (`x^-2`); `log` is the natural logarithm; `atan2`, `min`, `max` take two
//! arguments, the other functions one. Nesting is limited ([`MAX_NESTING`] levels of
//! parentheses, calls, signs and exponents; trees of height [`MAX_DEPTH`]) so that no input
//! can overflow the stack. A run of `+`/`-` (or `*`/`/`) of any length is one node
//! ([`AstKind::Chain`], its operands in a list, evaluated left to right as
//! `((a ± b) ± c) ± …`): its length is no nesting, so a flat sum of thousands of terms is
//! one level deep and nothing walks it recursively. Errors are `(column, kind)`; the caller
//! adds the key.

use super::error::ErrorKind;
pub use super::func::Func;

/// Largest height of an expression's tree: its nesting (a flat sum or product of any length
/// is one level, [`AstKind::Chain`]).
pub const MAX_DEPTH: usize = 1000;

/// Largest nesting of parentheses, calls, unary minus and exponents.
pub const MAX_NESTING: usize = 200;

/// A binary operator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BinOp {
    /// `+`
    Add,
    /// `-`
    Sub,
    /// `*`
    Mul,
    /// `/`
    Div,
    /// `^`
    Pow,
}

/// A node of the syntax tree with the 1-based column where its text starts.
#[derive(Debug, Clone, PartialEq)]
pub struct Ast {
    /// What the node is.
    pub kind: AstKind,
    /// Column of its first character.
    pub col: usize,
    /// Height of the tree below and including this node (1 for a leaf).
    depth: usize,
}

/// The kinds of [`Ast`] nodes (`pi` is parsed as the number π).
#[derive(Debug, Clone, PartialEq)]
pub enum AstKind {
    /// A number.
    Num(f64),
    /// A state, input, parameter or definition.
    Name(String),
    /// `-a`
    Neg(Box<Ast>),
    /// `a op b`
    Bin(BinOp, Box<Ast>, Box<Ast>),
    /// `a op₁ b op₂ c …` with two or more operators of one precedence level (`+`/`-` or
    /// `*`/`/`), left-associative: `((a op₁ b) op₂ c) …`. One node however long, so that
    /// the tree's height is its nesting.
    Chain(Box<Ast>, Vec<(BinOp, Ast)>),
    /// `f(a, …)` with the right number of arguments.
    Call(Func, Vec<Ast>),
}

/// A parse error: 1-based column and what is wrong.
pub type ParseError = (usize, ErrorKind);

/// Parses a whole expression.
pub fn parse_expr(text: &str) -> Result<Ast, ParseError> {
    let mut p = Parser::new(text)?;
    if p.peek() == &Tok::End {
        return Err((p.col(), syntax("empty expression")));
    }
    let e = p.expr()?;
    p.end()?;
    Ok(e)
}

/// Parses a definition `name = expr`: the name, its column, and the expression.
pub fn parse_definition(text: &str) -> Result<(String, usize, Ast), ParseError> {
    let mut p = Parser::new(text)?;
    let col = p.col();
    let name = match p.next() {
        Tok::Ident(name) => name,
        t => {
            return Err((
                col,
                syntax(format!(
                    "expected `name = expression`, found {}",
                    t.describe()
                )),
            ))
        }
    };
    if p.peek() != &Tok::Eq {
        let c = p.col();
        let found = p.next().describe();
        return Err((
            c,
            syntax(format!(
                "expected `=` after the name `{name}`, found {found}"
            )),
        ));
    }
    p.next();
    if p.peek() == &Tok::End {
        return Err((p.col(), syntax(format!("nothing after `{name} =`"))));
    }
    let e = p.expr()?;
    p.end()?;
    Ok((name, col, e))
}

/// Whether `s` is a valid name (the `name` rule of the grammar).
pub fn is_name(s: &str) -> bool {
    let mut chars = s.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// Visits every node of `ast` (children before parents).
pub fn visit(ast: &Ast, f: &mut impl FnMut(&Ast)) {
    match &ast.kind {
        AstKind::Num(_) | AstKind::Name(_) => {}
        AstKind::Neg(a) => visit(a, f),
        AstKind::Bin(_, a, b) => {
            visit(a, f);
            visit(b, f);
        }
        AstKind::Call(_, args) => args.iter().for_each(|a| visit(a, f)),
        AstKind::Chain(first, rest) => {
            visit(first, f);
            rest.iter().for_each(|(_, a)| visit(a, f));
        }
    }
    f(ast)
}

fn syntax(msg: impl Into<String>) -> ErrorKind {
    ErrorKind::Syntax(msg.into())
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Num(f64),
    Ident(String),
    Plus,
    Minus,
    Star,
    Slash,
    Caret,
    LParen,
    RParen,
    Comma,
    Eq,
    End,
}

impl Tok {
    fn describe(&self) -> String {
        match self {
            Tok::Num(v) => format!("the number {v}"),
            Tok::Ident(s) => format!("`{s}`"),
            Tok::Plus => "`+`".into(),
            Tok::Minus => "`-`".into(),
            Tok::Star => "`*`".into(),
            Tok::Slash => "`/`".into(),
            Tok::Caret => "`^`".into(),
            Tok::LParen => "`(`".into(),
            Tok::RParen => "`)`".into(),
            Tok::Comma => "`,`".into(),
            Tok::Eq => "`=`".into(),
            Tok::End => "the end".into(),
        }
    }
}

/// Splits the text into tokens with their columns (the last token is `End`).
fn lex(text: &str) -> Result<Vec<(Tok, usize)>, ParseError> {
    let chars: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        let col = i + 1;
        let single = match c {
            '+' => Some(Tok::Plus),
            '-' => Some(Tok::Minus),
            '*' => Some(Tok::Star),
            '/' => Some(Tok::Slash),
            '^' => Some(Tok::Caret),
            '(' => Some(Tok::LParen),
            ')' => Some(Tok::RParen),
            ',' => Some(Tok::Comma),
            '=' => Some(Tok::Eq),
            _ => None,
        };
        if let Some(t) = single {
            out.push((t, col));
            i += 1;
        } else if c.is_whitespace() {
            i += 1;
        } else if c.is_ascii_digit() || c == '.' {
            let start = i;
            let digits = |i: &mut usize| {
                let s = *i;
                while *i < chars.len() && chars[*i].is_ascii_digit() {
                    *i += 1;
                }
                *i - s
            };
            let mut n = digits(&mut i);
            if i < chars.len() && chars[i] == '.' {
                i += 1;
                n += digits(&mut i);
            }
            if n == 0 {
                return Err((col, syntax("`.` must be part of a number such as `.5`")));
            }
            if i < chars.len() && (chars[i] == 'e' || chars[i] == 'E') {
                i += 1;
                if i < chars.len() && (chars[i] == '+' || chars[i] == '-') {
                    i += 1;
                }
                if digits(&mut i) == 0 {
                    return Err((
                        col,
                        syntax("malformed number: the exponent after `e` needs digits"),
                    ));
                }
            }
            let s: String = chars[start..i].iter().collect();
            match s.parse::<f64>() {
                Ok(v) if v.is_finite() => out.push((Tok::Num(v), col)),
                _ => return Err((col, syntax(format!("number `{s}` is out of range")))),
            }
        } else if c.is_ascii_alphabetic() || c == '_' {
            let start = i;
            while i < chars.len() && (chars[i].is_ascii_alphanumeric() || chars[i] == '_') {
                i += 1;
            }
            out.push((Tok::Ident(chars[start..i].iter().collect()), col));
        } else {
            return Err((col, syntax(format!("unexpected character `{c}`"))));
        }
    }
    out.push((Tok::End, chars.len() + 1));
    Ok(out)
}

struct Parser {
    toks: Vec<(Tok, usize)>,
    pos: usize,
    nesting: usize,
}

impl Parser {
    fn new(text: &str) -> Result<Self, ParseError> {
        Ok(Parser {
            toks: lex(text)?,
            pos: 0,
            nesting: 0,
        })
    }
    fn peek(&self) -> &Tok {
        &self.toks[self.pos.min(self.toks.len() - 1)].0
    }
    fn col(&self) -> usize {
        self.toks[self.pos.min(self.toks.len() - 1)].1
    }
    fn next(&mut self) -> Tok {
        let t = self.peek().clone();
        if self.pos < self.toks.len() - 1 {
            self.pos += 1;
        }
        t
    }
    fn end(&mut self) -> Result<(), ParseError> {
        match self.peek() {
            Tok::End => Ok(()),
            Tok::RParen => Err((self.col(), syntax("`)` without a matching `(`"))),
            t => Err((
                self.col(),
                syntax(format!(
                    "expected an operator or the end, found {}",
                    t.describe()
                )),
            )),
        }
    }
    fn node(&self, kind: AstKind, col: usize) -> Result<Ast, ParseError> {
        let depth = 1 + match &kind {
            AstKind::Num(_) | AstKind::Name(_) => 0,
            AstKind::Neg(a) => a.depth,
            AstKind::Bin(_, a, b) => a.depth.max(b.depth),
            AstKind::Call(_, args) => args.iter().map(|a| a.depth).max().unwrap_or(0),
            AstKind::Chain(first, rest) => rest
                .iter()
                .map(|(_, a)| a.depth)
                .fold(first.depth, usize::max),
        };
        if depth > MAX_DEPTH {
            return Err((col, too_deep(MAX_DEPTH)));
        }
        Ok(Ast { kind, col, depth })
    }
    fn expr(&mut self) -> Result<Ast, ParseError> {
        let first = self.term()?;
        let mut rest = Vec::new();
        loop {
            let op = match self.peek() {
                Tok::Plus => BinOp::Add,
                Tok::Minus => BinOp::Sub,
                _ => return self.chain(first, rest),
            };
            self.next();
            rest.push((op, self.term()?));
        }
    }
    fn term(&mut self) -> Result<Ast, ParseError> {
        let first = self.unary()?;
        let mut rest = Vec::new();
        loop {
            let op = match self.peek() {
                Tok::Star => BinOp::Mul,
                Tok::Slash => BinOp::Div,
                _ => return self.chain(first, rest),
            };
            self.next();
            rest.push((op, self.unary()?));
        }
    }
    /// `first` alone, `Bin` for one operator, a [`AstKind::Chain`] for more (iteratively:
    /// the length of a sum is no nesting).
    fn chain(&self, first: Ast, mut rest: Vec<(BinOp, Ast)>) -> Result<Ast, ParseError> {
        let col = first.col;
        if rest.len() > 1 {
            return self.node(AstKind::Chain(Box::new(first), rest), col);
        }
        match rest.pop() {
            None => Ok(first),
            Some((op, b)) => self.node(AstKind::Bin(op, Box::new(first), Box::new(b)), col),
        }
    }
    /// Every recursion of the grammar passes through here: the nesting guard.
    fn unary(&mut self) -> Result<Ast, ParseError> {
        self.nesting += 1;
        if self.nesting > MAX_NESTING {
            return Err((self.col(), too_deep(MAX_NESTING)));
        }
        let r = if self.peek() == &Tok::Minus {
            let col = self.col();
            self.next();
            let a = self.unary()?;
            self.node(AstKind::Neg(Box::new(a)), col)
        } else {
            self.power()
        };
        self.nesting -= 1;
        r
    }
    fn power(&mut self) -> Result<Ast, ParseError> {
        let base = self.atom()?;
        if self.peek() != &Tok::Caret {
            return Ok(base);
        }
        self.next();
        let exp = self.unary()?;
        let col = base.col;
        self.node(AstKind::Bin(BinOp::Pow, Box::new(base), Box::new(exp)), col)
    }
    fn atom(&mut self) -> Result<Ast, ParseError> {
        let col = self.col();
        match self.next() {
            Tok::Num(v) => self.node(AstKind::Num(v), col),
            Tok::Ident(name) if self.peek() == &Tok::LParen => self.call(name, col),
            Tok::Ident(name) if name == "pi" => self.node(AstKind::Num(std::f64::consts::PI), col),
            Tok::Ident(name) => match Func::from_name(&name) {
                Some(f) => Err((
                    col,
                    syntax(format!(
                        "`{name}` is a function: write `{name}(…)` with {} argument{}",
                        f.arity(),
                        if f.arity() == 1 { "" } else { "s" }
                    )),
                )),
                None => self.node(AstKind::Name(name), col),
            },
            Tok::LParen => {
                let e = self.expr()?;
                match self.peek() {
                    Tok::RParen => {
                        self.next();
                        Ok(e)
                    }
                    t => Err((
                        self.col(),
                        syntax(format!(
                            "expected `)` to close the `(` at column {col}, found {}",
                            t.describe()
                        )),
                    )),
                }
            }
            t => Err((
                col,
                syntax(format!(
                    "expected a number, name or `(`, found {}",
                    t.describe()
                )),
            )),
        }
    }
    fn call(&mut self, name: String, col: usize) -> Result<Ast, ParseError> {
        let Some(func) = Func::from_name(&name) else {
            return Err((col, ErrorKind::UnknownFunction { name }));
        };
        let open = self.col();
        self.next(); // `(`
        let mut args = Vec::new();
        if self.peek() == &Tok::RParen {
            self.next();
        } else {
            loop {
                args.push(self.expr()?);
                let at = self.col();
                match self.next() {
                    Tok::Comma => continue,
                    Tok::RParen => break,
                    t => {
                        return Err((
                            at,
                            syntax(format!(
                                "expected `,` or `)` in the call of `{name}` opened at column {open}, found {}",
                                t.describe()
                            )),
                        ))
                    }
                }
            }
        }
        if args.len() != func.arity() {
            return Err((
                col,
                ErrorKind::Arity {
                    func: name,
                    expected: func.arity(),
                    got: args.len(),
                },
            ));
        }
        self.node(AstKind::Call(func, args), col)
    }
}

fn too_deep(limit: usize) -> ErrorKind {
    syntax(format!(
        "expression nested too deeply (more than {limit} levels)"
    ))
}
