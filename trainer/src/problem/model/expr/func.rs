//! [`Func`]: the functions of the expression language — `sin cos tan asin acos atan atan2 exp
//! log sqrt sinh cosh tanh abs min max` — with their names as written, their arity (two for
//! `atan2`, `min`, `max`, else one) and whether they are smooth (`abs`, `min`, `max` have a
//! kink). The parser reads them, the error messages list them, the compiler lowers them.

/// The functions of the language.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Func {
    /// sin x
    Sin,
    /// cos x
    Cos,
    /// tan x
    Tan,
    /// arcsin x
    Asin,
    /// arccos x
    Acos,
    /// arctan x
    Atan,
    /// atan2(y, x): the angle of the point (x, y)
    Atan2,
    /// eˣ
    Exp,
    /// natural logarithm
    Log,
    /// √x
    Sqrt,
    /// sinh x
    Sinh,
    /// cosh x
    Cosh,
    /// tanh x
    Tanh,
    /// |x| (not smooth at 0)
    Abs,
    /// min(a, b) (not smooth where a = b)
    Min,
    /// max(a, b) (not smooth where a = b)
    Max,
}

impl Func {
    /// All functions, in the order of the grammar.
    pub const ALL: [Func; 16] = [
        Func::Sin,
        Func::Cos,
        Func::Tan,
        Func::Asin,
        Func::Acos,
        Func::Atan,
        Func::Atan2,
        Func::Exp,
        Func::Log,
        Func::Sqrt,
        Func::Sinh,
        Func::Cosh,
        Func::Tanh,
        Func::Abs,
        Func::Min,
        Func::Max,
    ];
    /// The name written in expressions.
    pub fn name(self) -> &'static str {
        match self {
            Func::Sin => "sin",
            Func::Cos => "cos",
            Func::Tan => "tan",
            Func::Asin => "asin",
            Func::Acos => "acos",
            Func::Atan => "atan",
            Func::Atan2 => "atan2",
            Func::Exp => "exp",
            Func::Log => "log",
            Func::Sqrt => "sqrt",
            Func::Sinh => "sinh",
            Func::Cosh => "cosh",
            Func::Tanh => "tanh",
            Func::Abs => "abs",
            Func::Min => "min",
            Func::Max => "max",
        }
    }
    /// The function of that name.
    pub fn from_name(name: &str) -> Option<Func> {
        Func::ALL.into_iter().find(|f| f.name() == name)
    }
    /// Number of arguments.
    pub fn arity(self) -> usize {
        match self {
            Func::Atan2 | Func::Min | Func::Max => 2,
            _ => 1,
        }
    }
    /// False for `abs`, `min`, `max`: their derivatives jump at a kink.
    pub fn is_smooth(self) -> bool {
        !matches!(self, Func::Abs | Func::Min | Func::Max)
    }
    /// The names, separated by blanks (for messages).
    pub fn list() -> String {
        Func::ALL.map(Func::name).join(" ")
    }
}
