//! The body of one generated model function: the straight-line statements of a lowered
//! [`Function`], with its temporaries register-allocated and its outputs written as soon as
//! they are computed.

use proc_macro2::TokenStream;
use quote::{format_ident, quote};

use mpc_dsl::ops::{BinaryOp, UnaryOp};
use mpc_dsl::{Instr, Operand};

use super::{lit, ul};
use crate::lower::{Arg, Function, Target};
use crate::options::Scalar;

/// Which helpers the emitted functions call (the `functions` module defines only those).
#[derive(Default)]
pub(super) struct Uses {
    pub(super) sign: bool,
    pub(super) step: bool,
    pub(super) powi: bool,
}

/// The statements computing `f` and writing its outputs: temporaries, then zeroing (a slice
/// fill, which compiles to a memset; nalgebra's `Matrix::fill` is an element loop) of
/// every output matrix and the writes of its nonzero entries, then the returned vector.
pub(super) fn body(
    f: &Function,
    s: Scalar,
    mats: &[&str],
    ret: Option<TokenStream>,
    uses: &mut Uses,
) -> TokenStream {
    let instrs = f.program.instrs();
    let (slots, nslots) = allocate_slots(instrs);
    let (writes_at, late) = output_writes(f);
    let e = Statements {
        f,
        s,
        slots: &slots,
    };
    let mut stmts = Vec::with_capacity(instrs.len());
    for (i, ins) in instrs.iter().enumerate() {
        let t = format_ident!("t{}", slots[i]);
        let v = e.instr(ins, uses);
        stmts.push(quote!(#t = #v;));
        for &(o, tg) in &writes_at[i] {
            stmts.push(e.write(o, tg));
        }
    }
    let late: Vec<_> = late.into_iter().map(|(o, t)| e.write(o, t)).collect();
    let decls = (0..nslots).map(|k| {
        let t = format_ident!("t{}", k);
        quote!(let mut #t: Real;)
    });
    let fills = mats.iter().map(|m| {
        let m = format_ident!("{}", m);
        quote!(#m.as_mut_slice().fill(0.0);)
    });
    match ret {
        Some(ty) => quote! {
            #(#fills)*
            let mut r = <#ty>::zeros();
            #(#decls)*
            #(#stmts)*
            #(#late)*
            r
        },
        None => quote! {
            #(#fills)*
            #(#decls)*
            #(#stmts)*
            #(#late)*
        },
    }
}

/// Register allocation: the variable `t<slot>` of every instruction's result, and how many
/// variables there are. A temporary's variable is reused once its last reader has run, so a
/// function declares about as many variables as values are live at once (not one per
/// instruction: thousands of nested `let` scopes make LLVM's debug-info pass recurse too
/// deep).
fn allocate_slots(instrs: &[Instr]) -> (Vec<usize>, usize) {
    let n = instrs.len();
    let mut last_use = vec![0usize; n];
    for (i, ins) in instrs.iter().enumerate() {
        last_use[i] = i;
        for o in ins.operands() {
            if let Operand::Temp(t) = o {
                last_use[t as usize] = i;
            }
        }
    }
    let mut slots = vec![0usize; n];
    let mut free: Vec<usize> = Vec::new();
    let mut nslots = 0usize;
    for (i, ins) in instrs.iter().enumerate() {
        let mut seen = [u32::MAX; 2];
        for (k, o) in ins.operands().enumerate() {
            if let Operand::Temp(t) = o {
                if last_use[t as usize] == i && !seen.contains(&t) {
                    free.push(slots[t as usize]);
                }
                seen[k] = t;
            }
        }
        slots[i] = free.pop().unwrap_or_else(|| {
            nslots += 1;
            nslots - 1
        });
        if last_use[i] == i {
            // Read by no later instruction (an output only): free after its writes.
            free.push(slots[i]);
        }
    }
    (slots, nslots)
}

/// An output to write: the value and where it goes.
type Write = (Operand, Target);

/// When each output is written: the outputs computed by instruction `i` right after it
/// (`writes_at[i]`), inputs and nonzero constants at the end (`late`), zeros never (the
/// output matrices are zero-filled first).
fn output_writes(f: &Function) -> (Vec<Vec<Write>>, Vec<Write>) {
    let mut writes_at: Vec<Vec<Write>> = vec![Vec::new(); f.program.instrs().len()];
    let mut late = Vec::new();
    for (o, t) in f.program.outputs().iter().zip(&f.outputs) {
        match *o {
            Operand::Const(0.0) => {} // zeros are already there
            Operand::Temp(k) => writes_at[k as usize].push((*o, *t)),
            _ => late.push((*o, *t)),
        }
    }
    (writes_at, late)
}

/// Emits the expressions and statements of one function, its variables allocated.
struct Statements<'a> {
    f: &'a Function,
    s: Scalar,
    slots: &'a [usize],
}

impl Statements<'_> {
    /// An operand: an argument entry (`x[3]`), a literal or a temporary's variable.
    fn operand(&self, o: Operand) -> TokenStream {
        match o {
            Operand::Input(k) => {
                let (arg, i) = self.f.inputs[k as usize];
                let name = match arg {
                    Arg::X => quote!(x),
                    Arg::U => quote!(u),
                    Arg::P => quote!(p),
                    Arg::Pi => quote!(pi),
                    Arg::Mu => quote!(mu),
                };
                let i = ul(i);
                quote!(#name[#i])
            }
            Operand::Const(c) => lit(c, self.s),
            Operand::Temp(t) => {
                let id = format_ident!("t{}", self.slots[t as usize]);
                quote!(#id)
            }
        }
    }

    /// The write of output `o` to `t`: `r[i] = ..;` or `m[(i, j)] = ..;`.
    fn write(&self, o: Operand, t: Target) -> TokenStream {
        let v = self.operand(o);
        match t {
            Target::Ret(i) => {
                let i = ul(i);
                quote!(r[#i] = #v;)
            }
            Target::Mat(m, i, j) => {
                let m = format_ident!("{}", m);
                let (i, j) = (ul(i), ul(j));
                quote!(#m[(#i, #j)] = #v;)
            }
        }
    }

    /// The expression of one instruction; notes in `uses` the helpers it calls.
    fn instr(&self, ins: &Instr, uses: &mut Uses) -> TokenStream {
        match *ins {
            Instr::Unary(op, a) => self.unary(op, a, uses),
            Instr::PowI(a, n) => {
                uses.powi = true;
                let a = self.operand(a);
                let n = proc_macro2::Literal::i32_unsuffixed(n);
                quote!(powi(#a, #n))
            }
            Instr::Binary(op, a, b) => self.binary(op, a, b),
        }
    }

    fn unary(&self, op: UnaryOp, a: Operand, uses: &mut Uses) -> TokenStream {
        let a = self.operand(a);
        match op {
            UnaryOp::Neg => quote!(-#a),
            UnaryOp::Sign => {
                uses.sign = true;
                quote!(sign(#a))
            }
            UnaryOp::Step => {
                uses.step = true;
                quote!(step(#a))
            }
            UnaryOp::Abs => {
                let m = libm_fn("fabs", self.s);
                quote!(#m(#a))
            }
            other => {
                let m = libm_fn(other.name(), self.s);
                quote!(#m(#a))
            }
        }
    }

    fn binary(&self, op: BinaryOp, a: Operand, b: Operand) -> TokenStream {
        let (a, b) = (self.operand(a), self.operand(b));
        let libm = |name: &str| {
            let m = libm_fn(name, self.s);
            quote!(#m(#a, #b))
        };
        match op {
            BinaryOp::Add => quote!(#a + #b),
            BinaryOp::Sub => quote!(#a - #b),
            BinaryOp::Mul => quote!(#a * #b),
            BinaryOp::Div => quote!(#a / #b),
            BinaryOp::Pow => libm("pow"),
            BinaryOp::Atan2 => libm("atan2"),
            BinaryOp::Min => libm("fmin"),
            BinaryOp::Max => libm("fmax"),
        }
    }
}

/// The `libm` function `name` for the scalar type (`sin`, or `sinf` for `f32`).
fn libm_fn(name: &str, s: Scalar) -> TokenStream {
    let id = match s {
        Scalar::F64 => format_ident!("{}", name),
        Scalar::F32 => format_ident!("{}f", name),
    };
    quote!(mpc_runtime::libm::#id)
}
