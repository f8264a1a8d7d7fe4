//! Procedural macros behind relume's node API, re-exported by relume-core:
//!
//! - `#[derive(Params)]` on a node struct: each field is a parameter (its doc comment is the
//!   help text; `#[param(default = …, test = …, range = a..=b, unit = "…", rgb, output,
//!   extensions = ["…"], also_reads = f)]` the rest; `#[param(flatten)]` takes in a group of parameters that
//!   derives `Params` itself), the struct's doc comment is the node's doc (the editor tooltip).
//! - `params! { pub struct X { pub name: Type = default, key = …; … } }`: the same struct with
//!   each parameter on one line (`params_block`); it expands to the derive above.
//! - `#[derive(ParamEnum)]` on an enum of unit variants: a choice parameter whose variants are
//!   listed once; an unknown name is a load error, never a fallback.
//! - `#[node(category = "…", outputs = [name, …], metrics = ["…", …], version = N,
//!   caching = Never | Keyed, kind = "…")]` on `impl X { fn run … }`: turns the block into
//!   `impl Node for X`, taking the ports from `run`'s signature.
//!
//! A node declared with them, registered and run in a two-node graph (the value on the edge
//! is any type implementing `PortValue`; the pipeline crates use images, scenes and tensors):
//!
//! ```
//! use relume_core::{node, outputs, params, Engine, Graph, NodeError, PortValue, Registry, RunCtx, RunOptions};
//!
//! /// A number on an edge.
//! #[derive(Clone, Debug, PartialEq)]
//! pub struct Num(f64);
//!
//! impl PortValue for Num {
//!     const NAME: &'static str = "Num";
//!     const COLOR: [u8; 3] = [200, 200, 80];
//!     fn byte_size(&self) -> usize { 8 }
//!     fn encode(&self) -> Vec<u8> { self.0.to_le_bytes().to_vec() }
//!     fn decode(b: &[u8]) -> Option<Self> { Some(Num(f64::from_le_bytes(b.try_into().ok()?))) }
//! }
//!
//! params! {
//!     /// Emits a constant.
//!     pub struct Constant {
//!         /// the value emitted
//!         pub value: f64 = 1.0, range = -100.0..=100.0;
//!     }
//! }
//! outputs!(pub ConstantOut { out: Num });
//!
//! #[node(category = "example")]
//! impl Constant {
//!     fn run(&self, _: (), _cx: &RunCtx) -> Result<ConstantOut, NodeError> {
//!         Ok(ConstantOut { out: Num(self.value) })
//!     }
//! }
//!
//! params! {
//!     /// Multiplies its input by a factor.
//!     pub struct Scale {
//!         /// the factor
//!         pub factor: f64 = 2.0, range = 0.0..=10.0;
//!     }
//! }
//!
//! #[node(category = "example", outputs = [out])]
//! impl Scale {
//!     fn run(&self, x: &Num, _cx: &RunCtx) -> Result<Num, NodeError> {
//!         Ok(Num(x.0 * self.factor))
//!     }
//! }
//!
//! let mut registry = Registry::new();
//! registry.add::<Constant>().add::<Scale>();
//! let graph = Graph::parse(
//!     r#"(version: 1,
//!         nodes: { "c": (kind: "Constant", params: (value: 3.0)), "s": (kind: "Scale", params: ()) },
//!         edges: [("c.out", "s.x")],
//!         outputs: { "result": "s.out" })"#,
//!     None,
//! )
//! .unwrap();
//! let run = Engine::new(registry).run(&graph, &RunOptions::default()).unwrap();
//! assert_eq!(run.output("result").unwrap().get::<Num>(), Some(&Num(6.0)), "3 × the default factor 2");
//!
//! // The schema comes from the declaration: a value outside the stated range is refused
//! // when the graph is validated, before anything runs.
//! let mut registry = Registry::new();
//! registry.add::<Constant>().add::<Scale>();
//! let bad = Graph::parse(
//!     r#"(version: 1, nodes: { "c": (kind: "Constant", params: ()), "s": (kind: "Scale", params: (factor: 20.0)) },
//!         edges: [("c.out", "s.x")], outputs: { "result": "s.out" })"#,
//!     None,
//! )
//! .unwrap();
//! let refused = bad.validate(&registry).unwrap_err().to_string();
//! assert!(refused.contains("factor"), "{refused}");
//! ```

mod params_block;

use proc_macro::TokenStream;
use proc_macro2::{Span, TokenStream as Tokens};
use quote::{format_ident, quote};
use syn::{
    parse_macro_input, spanned::Spanned, Data, DeriveInput, Expr, Fields, GenericArgument, ImplItem, ImplItemFn, ItemImpl, Lit,
    PathArguments, ReturnType, Type,
};

/// The doc comment of an item, one string per line (leading space kept, as rustdoc has it).
fn doc_lines(attrs: &[syn::Attribute]) -> Vec<String> {
    attrs
        .iter()
        .filter(|a| a.path().is_ident("doc"))
        .filter_map(|a| match &a.meta {
            syn::Meta::NameValue(nv) => match &nv.value {
                Expr::Lit(syn::ExprLit { lit: Lit::Str(s), .. }) => Some(s.value()),
                _ => None,
            },
            _ => None,
        })
        .collect()
}

fn err(span: Span, msg: &str) -> Tokens {
    syn::Error::new(span, msg).to_compile_error()
}

/// What a field's Rust type makes of the parameter.
enum Shape {
    Float,
    Int,
    Bool,
    Text,
    File,
    Triple,
    Enum,
}

fn last_ident(ty: &Type) -> Option<String> {
    match ty {
        Type::Path(p) => p.path.segments.last().map(|s| s.ident.to_string()),
        _ => None,
    }
}

fn shape_of(ty: &Type) -> Shape {
    if let Type::Array(a) = ty {
        if let Expr::Lit(syn::ExprLit { lit: Lit::Int(n), .. }) = &a.len {
            if n.base10_digits() == "3" {
                return Shape::Triple;
            }
        }
    }
    match last_ident(ty).as_deref() {
        Some("f32" | "f64") => Shape::Float,
        Some("i8" | "i16" | "i32" | "i64" | "u8" | "u16" | "u32" | "u64" | "usize" | "isize") => Shape::Int,
        Some("bool") => Shape::Bool,
        Some("String") => Shape::Text,
        Some("PathBuf") => Shape::File,
        Some("Vec3" | "Vec3A" | "DVec3") => Shape::Triple,
        _ => Shape::Enum,
    }
}

#[derive(Default)]
struct FieldAttrs {
    default: Option<Expr>,
    test: Option<Expr>,
    range: Option<(Expr, Expr)>,
    unit: Option<String>,
    rgb: bool,
    output: bool,
    flatten: bool,
    extensions: Vec<syn::LitStr>,
    also_reads: Option<syn::Path>,
}

fn field_attrs(f: &syn::Field) -> syn::Result<FieldAttrs> {
    let mut out = FieldAttrs::default();
    for a in f.attrs.iter().filter(|a| a.path().is_ident("param")) {
        a.parse_nested_meta(|meta| {
            if meta.path.is_ident("default") {
                out.default = Some(meta.value()?.parse()?);
            } else if meta.path.is_ident("test") {
                out.test = Some(meta.value()?.parse()?);
            } else if meta.path.is_ident("range") {
                let e: Expr = meta.value()?.parse()?;
                match e {
                    Expr::Range(r) if r.start.is_some() && r.end.is_some() && matches!(r.limits, syn::RangeLimits::Closed(_)) => {
                        out.range = Some((*r.start.unwrap(), *r.end.unwrap()));
                    }
                    _ => return Err(meta.error("range must be written `min..=max`")),
                }
            } else if meta.path.is_ident("unit") {
                let s: syn::LitStr = meta.value()?.parse()?;
                out.unit = Some(s.value());
            } else if meta.path.is_ident("rgb") {
                out.rgb = true;
            } else if meta.path.is_ident("output") {
                out.output = true;
            } else if meta.path.is_ident("flatten") {
                out.flatten = true;
            } else if meta.path.is_ident("also_reads") {
                out.also_reads = Some(meta.value()?.parse()?);
            } else if meta.path.is_ident("extensions") {
                let list: syn::ExprArray = meta.value()?.parse()?;
                for e in list.elems {
                    match e {
                        Expr::Lit(syn::ExprLit { lit: Lit::Str(s), .. }) => out.extensions.push(s),
                        e => return Err(syn::Error::new(e.span(), "extensions = [\"exr\", \"png\"]: lower case, without the dot")),
                    }
                }
            } else {
                return Err(meta.error("unknown #[param] key (default, test, range, unit, rgb, output, flatten, extensions, also_reads)"));
            }
            Ok(())
        })?;
    }
    Ok(out)
}

/// `#[derive(Params)]`: the parameter schema and typed construction of a node's parameters,
/// and its doc comment as `Documented::DOC`.
#[proc_macro_derive(Params, attributes(param))]
pub fn derive_params(input: TokenStream) -> TokenStream {
    let input = parse_macro_input!(input as DeriveInput);
    match params_impl(&input) {
        Ok(t) => t.into(),
        Err(e) => e.to_compile_error().into(),
    }
}

fn params_impl(input: &DeriveInput) -> syn::Result<Tokens> {
    let name = &input.ident;
    let doc = doc_lines(&input.attrs).join("\n");
    let Data::Struct(data) = &input.data else {
        return Err(syn::Error::new(input.span(), "derive(Params) takes a struct"));
    };
    let fields: Vec<&syn::Field> = match &data.fields {
        Fields::Named(n) => n.named.iter().collect(),
        Fields::Unit => Vec::new(),
        Fields::Unnamed(_) => return Err(syn::Error::new(input.span(), "derive(Params) takes named fields or a unit struct")),
    };
    let c = quote!(::relume_core);
    let mut specs = Vec::new();
    let mut inits = Vec::new();
    for f in &fields {
        let ident = f.ident.as_ref().unwrap();
        let pname = ident.to_string();
        let ty = &f.ty;
        let a = field_attrs(f)?;
        if a.flatten {
            // A group of parameters declared once (its own `derive(Params)`), listed as the
            // node's own: same names, no prefix.
            specs.push(quote!(specs.extend(<#ty as #c::Params>::schema().0);));
            inits.push(quote!(#ident: <#ty as #c::Params>::from_values(v)?));
            continue;
        }
        let help = doc_lines(&f.attrs).iter().map(|l| l.trim()).collect::<Vec<_>>().join(" ");
        let unit = a.unit.clone().unwrap_or_default();
        let range = |kind: &str| -> syn::Result<(Expr, Expr)> {
            a.range
                .clone()
                .ok_or_else(|| syn::Error::new(f.span(), format!("{kind} parameter `{pname}` needs #[param(range = min..=max)]")))
        };
        // The kind, how a value written in `#[param(default = …, test = …)]` becomes a
        // `ParamValue`, and how the field is read from checked values.
        type ValueOf<'x> = Box<dyn Fn(&Expr) -> syn::Result<Tokens> + 'x>;
        let (kind, value_of, init): (Tokens, ValueOf, Tokens) = match shape_of(ty) {
            Shape::Float => {
                let (lo, hi) = range("float")?;
                let v = Box::new(|e: &Expr| Ok(quote!(#c::ParamValue::Float((#e) as f64))));
                (quote!(#c::ParamKind::Float { min: (#lo) as f64, max: (#hi) as f64 }), v, quote!(v.float(#pname) as #ty))
            }
            Shape::Int => {
                let (lo, hi) = range("integer")?;
                let v = Box::new(|e: &Expr| Ok(quote!(#c::ParamValue::Int((#e) as i64))));
                let init = quote!(<#ty as ::core::convert::TryFrom<i64>>::try_from(v.int(#pname))
                    .map_err(|_| #c::NodeError::param(#pname, "does not fit its Rust type"))?);
                (quote!(#c::ParamKind::Int { min: (#lo) as i64, max: (#hi) as i64 }), v, init)
            }
            Shape::Bool => (quote!(#c::ParamKind::Bool), Box::new(|e: &Expr| Ok(quote!(#c::ParamValue::Bool(#e)))), quote!(v.bool(#pname))),
            Shape::Text => (
                quote!(#c::ParamKind::Text),
                Box::new(|e: &Expr| Ok(quote!(#c::ParamValue::Text(::std::string::String::from(#e))))),
                quote!(v.text(#pname).to_string()),
            ),
            Shape::File => {
                let kind = if a.output { quote!(#c::ParamKind::OutputFile) } else { quote!(#c::ParamKind::InputFile) };
                (kind, Box::new(|e: &Expr| Ok(quote!(#c::ParamValue::Text(::std::string::String::from(#e))))), quote!(v.path(#pname)))
            }
            Shape::Triple => {
                let kind = if a.rgb {
                    let (lo, hi) = range("rgb")?;
                    quote!(#c::ParamKind::Rgb { min: (#lo) as f64, max: (#hi) as f64 })
                } else {
                    quote!(#c::ParamKind::Vec3)
                };
                let v = Box::new(|e: &Expr| match e {
                    Expr::Tuple(t) if t.elems.len() == 3 => {
                        let e = t.elems.iter();
                        Ok(quote!(#c::ParamValue::Tuple(vec![#(#c::ParamValue::Float((#e) as f64)),*])))
                    }
                    e => Err(syn::Error::new(e.span(), "a triple's value is written (x, y, z)")),
                });
                (kind, v, quote!(::core::convert::From::from(v.triple(#pname).map(|x| x as f32))))
            }
            Shape::Enum => {
                let v = Box::new(|e: &Expr| match e {
                    Expr::Path(p) if p.path.get_ident().is_some() => {
                        let var = p.path.get_ident().unwrap();
                        Ok(quote!(#c::ParamValue::Ident(#c::ParamEnum::name(&<#ty>::#var).to_string())))
                    }
                    e => Err(syn::Error::new(e.span(), "an enum parameter's value is a variant name")),
                });
                let init = quote!(<#ty as #c::ParamEnum>::from_name(v.variant(#pname))
                    .ok_or_else(|| #c::NodeError::param(#pname, format!("`{}` is not one of {}", v.variant(#pname), <#ty as #c::ParamEnum>::VARIANTS.join(", "))))?);
                (quote!(#c::ParamKind::Enum(<#ty as #c::ParamEnum>::VARIANTS)), v, init)
            }
        };
        let option = |e: Option<&Expr>| -> syn::Result<Tokens> {
            Ok(match e {
                Some(e) => {
                    let v = value_of(e)?;
                    quote!(::core::option::Option::Some(#v))
                }
                None => quote!(::core::option::Option::None),
            })
        };
        // A text parameter without a default defaults to the empty string.
        let default = match (&a.default, shape_of(ty)) {
            (None, Shape::Text) => quote!(::core::option::Option::Some(#c::ParamValue::Text(::std::string::String::new()))),
            (d, _) => option(d.as_ref())?,
        };
        let test = option(a.test.as_ref())?;
        let extensions = &a.extensions;
        let also_reads = match &a.also_reads {
            Some(f) => quote!(::core::option::Option::Some(#c::FileList(#f))),
            None => quote!(::core::option::Option::None),
        };
        specs.push(
            quote!(specs.push(#c::ParamSpec { name: #pname, kind: #kind, default: #default, unit: #unit, help: #help, test: #test, extensions: &[#(#extensions),*], also_reads: #also_reads });),
        );
        inits.push(quote!(#ident: #init));
    }
    let construct = match &data.fields {
        Fields::Unit => quote!(#name),
        _ => quote!(#name { #(#inits),* }),
    };
    let (ig, tg, wc) = input.generics.split_for_impl();
    Ok(quote! {
        impl #ig #c::Params for #name #tg #wc {
            fn schema() -> #c::Schema {
                #[allow(unused_mut)]
                let mut specs = ::std::vec::Vec::new();
                #(#specs)*
                #c::Schema(specs)
            }
            #[allow(unused_variables)]
            fn from_values(v: &#c::ParamValues) -> ::core::result::Result<Self, #c::NodeError> {
                ::core::result::Result::Ok(#construct)
            }
        }
        impl #ig #c::Documented for #name #tg #wc {
            const DOC: &'static str = #doc;
        }
    })
}

/// `params! { … }`: a parameter struct with one line per parameter; see `params_block`.
#[proc_macro]
pub fn params(input: TokenStream) -> TokenStream {
    params_block::expand(parse_macro_input!(input as params_block::Block)).into()
}

/// `#[derive(ParamEnum)]`: a choice parameter; variants are named once, in declaration order.
#[proc_macro_derive(ParamEnum)]
pub fn derive_param_enum(input: TokenStream) -> TokenStream {
    let input = parse_macro_input!(input as DeriveInput);
    let name = &input.ident;
    let Data::Enum(data) = &input.data else {
        return err(input.span(), "derive(ParamEnum) takes an enum").into();
    };
    if let Some(v) = data.variants.iter().find(|v| !matches!(v.fields, Fields::Unit)) {
        return err(v.span(), "ParamEnum variants carry no data").into();
    }
    let idents: Vec<_> = data.variants.iter().map(|v| &v.ident).collect();
    let names: Vec<String> = idents.iter().map(|i| i.to_string()).collect();
    let c = quote!(::relume_core);
    quote! {
        impl #c::ParamEnum for #name {
            const VARIANTS: &'static [&'static str] = &[#(#names),*];
            fn from_name(s: &str) -> ::core::option::Option<Self> {
                match s {
                    #(#names => ::core::option::Option::Some(#name::#idents),)*
                    _ => ::core::option::Option::None,
                }
            }
            fn name(&self) -> &'static str {
                match self {
                    #(#name::#idents => #names,)*
                }
            }
        }
    }
    .into()
}

#[derive(Default)]
struct NodeArgs {
    category: Option<String>,
    version: Option<syn::LitInt>,
    kind: Option<String>,
    caching: Option<syn::Ident>,
    sharded: bool,
    metrics: Vec<syn::LitStr>,
    outputs: Option<Vec<syn::Ident>>,
}

/// `#[node(category = "image", version = 2, caching = Never, kind = "Name")]` on an inherent
/// `impl X { fn run(&self, inputs: In, cx: &RunCtx) -> Result<Out, NodeError> { … } … }`:
/// implements `Node` for `X` (kind defaults to the type's name, version to 1, caching to
/// `Auto`); `Inputs` and `Outputs` come from `run`'s signature; an optional
/// `fn memory(&self, inputs: &[Option<PortSize>]) -> MemoryEstimate` and an optional
/// `fn work(&self, inputs: &[Option<PortSize>]) -> Option<f64>` go into the trait too; other
/// items stay in `impl X`.
///
/// With `sharded`, the `impl` has `fn shard`, `fn run_items` and `fn gather` instead of
/// `fn run` (relume-core's `Sharded`): they go into `impl Sharded for X`, `Inputs` and
/// `Outputs` come from `gather`'s signature, `Partial` from `run_items`' result, and `run`
/// is `shard::run_all`.
#[proc_macro_attribute]
pub fn node(attr: TokenStream, item: TokenStream) -> TokenStream {
    let mut args = NodeArgs::default();
    let parser = syn::meta::parser(|meta| {
        if meta.path.is_ident("category") {
            args.category = Some(meta.value()?.parse::<syn::LitStr>()?.value());
        } else if meta.path.is_ident("version") {
            args.version = Some(meta.value()?.parse()?);
        } else if meta.path.is_ident("kind") {
            args.kind = Some(meta.value()?.parse::<syn::LitStr>()?.value());
        } else if meta.path.is_ident("caching") {
            args.caching = Some(meta.value()?.parse()?);
        } else if meta.path.is_ident("sharded") {
            args.sharded = true;
        } else if meta.path.is_ident("outputs") {
            let list: syn::ExprArray = meta.value()?.parse()?;
            let mut names = Vec::new();
            for e in list.elems {
                match e {
                    Expr::Path(p) if p.path.get_ident().is_some() => names.push(p.path.get_ident().unwrap().clone()),
                    other => return Err(syn::Error::new(other.span(), "outputs = [name, …]: port names")),
                }
            }
            args.outputs = Some(names);
        } else if meta.path.is_ident("metrics") {
            let list: syn::ExprArray = meta.value()?.parse()?;
            for e in list.elems {
                match e {
                    Expr::Lit(syn::ExprLit { lit: Lit::Str(s), .. }) => args.metrics.push(s),
                    other => return Err(syn::Error::new(other.span(), "metrics = [\"name\", …]: string literals")),
                }
            }
        } else {
            return Err(meta.error("unknown #[node] key (category, version, caching, kind, sharded, outputs, metrics)"));
        }
        Ok(())
    });
    parse_macro_input!(attr with parser);
    let imp = parse_macro_input!(item as ItemImpl);
    match node_impl(args, imp) {
        Ok(t) => t.into(),
        Err(e) => e.to_compile_error().into(),
    }
}

fn node_impl(args: NodeArgs, imp: ItemImpl) -> syn::Result<Tokens> {
    if imp.trait_.is_some() {
        return Err(syn::Error::new(imp.span(), "#[node] goes on an inherent `impl X { fn run … }`"));
    }
    let self_ty = &imp.self_ty;
    let kind = match args.kind {
        Some(k) => k,
        None => last_ident(self_ty).ok_or_else(|| syn::Error::new(self_ty.span(), "#[node] needs a named type"))?,
    };
    let category = args.category.ok_or_else(|| syn::Error::new(Span::call_site(), "#[node] needs category = \"…\""))?;
    let version = args.version.map(|v| quote!(#v)).unwrap_or(quote!(1));
    let caching = args.caching.unwrap_or_else(|| format_ident!("Auto"));
    let metrics = &args.metrics;
    let mut run = None;
    // `Node`'s optional functions, written in the impl and moved into the trait impl.
    let mut trait_fns = Vec::new();
    let mut shard_fns: [Option<ImplItemFn>; 3] = [None, None, None];
    let mut rest = Vec::new();
    for item in imp.items {
        match item {
            ImplItem::Fn(f) if f.sig.ident == "run" => run = Some(f),
            ImplItem::Fn(f) if f.sig.ident == "memory" || f.sig.ident == "work" => trait_fns.push(f),
            ImplItem::Fn(f) if args.sharded && ["shard", "run_items", "gather"].contains(&f.sig.ident.to_string().as_str()) => {
                let at = ["shard", "run_items", "gather"].iter().position(|n| f.sig.ident == n).unwrap();
                shard_fns[at] = Some(f);
            }
            other => rest.push(other),
        }
    }
    let c = quote!(::relume_core);
    let rest = if rest.is_empty() { quote!() } else { quote!(impl #self_ty { #(#rest)* }) };
    let head = quote! {
        const KIND: &'static str = #kind;
        const VERSION: u32 = #version;
        const CATEGORY: &'static str = #category;
        const CACHING: #c::Caching = #c::Caching::#caching;
        const METRICS: &'static [&'static str] = &[#(#metrics),*];
    };
    if args.sharded {
        if let Some(run) = run {
            return Err(syn::Error::new(run.sig.span(), "a sharded node has `shard`, `run_items` and `gather` instead of `run`"));
        }
        let [Some(shard), Some(run_items), Some(gather)] = shard_fns else {
            return Err(syn::Error::new(Span::call_site(), "#[node(sharded)] needs `fn shard`, `fn run_items` and `fn gather`"));
        };
        let inputs = match gather.sig.inputs.iter().nth(1) {
            Some(syn::FnArg::Typed(t)) => match t.ty.as_ref() {
                Type::Reference(r) => input_type(&r.elem)?,
                other => return Err(syn::Error::new(other.span(), "gather takes (&self, &inputs, parts, cx)")),
            },
            _ => return Err(syn::Error::new(gather.sig.span(), "gather takes (&self, &inputs, parts, cx)")),
        };
        let outputs = output_type(&gather.sig.output)?;
        let partial = output_type(&run_items.sig.output)?;
        return Ok(quote! {
            impl #c::Node for #self_ty {
                #head
                type Inputs<'a> = #inputs;
                type Outputs = #outputs;
                fn run(&self, inputs: Self::Inputs<'_>, cx: &#c::RunCtx) -> Result<Self::Outputs, #c::NodeError> {
                    #c::shard::run_all(self, &inputs, cx)
                }
                fn sharded() -> Option<::std::sync::Arc<dyn #c::shard::DynSharded>> {
                    Some(::std::sync::Arc::new(#c::shard::ShardEntry::<Self>::new()))
                }
                #(#trait_fns)*
            }
            impl #c::Sharded for #self_ty {
                type Partial = #partial;
                #shard
                #run_items
                #gather
            }
            #rest
        });
    }
    let run = run.ok_or_else(|| syn::Error::new(Span::call_site(), "#[node] impl has no `fn run`"))?;
    if let Some(names) = &args.outputs {
        return ports_from_signature(&head, self_ty, run, trait_fns, rest, names);
    }
    let inputs = match run.sig.inputs.iter().nth(1) {
        Some(syn::FnArg::Typed(t)) => input_type(&t.ty)?,
        _ => return Err(syn::Error::new(run.sig.span(), "run takes (&self, inputs, cx)")),
    };
    let outputs = output_type(&run.sig.output)?;
    Ok(quote! {
        impl #c::Node for #self_ty {
            #head
            type Inputs<'a> = #inputs;
            type Outputs = #outputs;
            #run
            #(#trait_fns)*
        }
        #rest
    })
}

/// `fn run(&self, a: &A, b: &B, cx: &RunCtx) -> Result<O, NodeError>` (or `-> Result<(O1, O2),
/// NodeError>` with as many names in `outputs = […]`): the ports are the arguments and the
/// named parts of the result. The macro declares the port structs (hidden), implements `Node`
/// with a `run` that unpacks them, and keeps the written `run` as the inherent `run_ports`.
fn ports_from_signature(
    head: &Tokens,
    self_ty: &Type,
    mut run: ImplItemFn,
    trait_fns: Vec<ImplItemFn>,
    rest: Tokens,
    names: &[syn::Ident],
) -> syn::Result<Tokens> {
    let c = quote!(::relume_core);
    let base = last_ident(self_ty).unwrap_or_default();
    let in_name = format_ident!("{base}Ports");
    let out_name = format_ident!("{base}Results");
    let args: Vec<&syn::FnArg> = run.sig.inputs.iter().collect();
    if args.len() < 2 || !matches!(args[0], syn::FnArg::Receiver(_)) {
        return Err(syn::Error::new(run.sig.span(), "run takes (&self, one `name: &Type` per input port, cx: &RunCtx)"));
    }
    let mut ports = Vec::new();
    for a in &args[1..args.len() - 1] {
        let syn::FnArg::Typed(t) = a else { unreachable!() };
        let (syn::Pat::Ident(id), Type::Reference(r)) = (t.pat.as_ref(), t.ty.as_ref()) else {
            return Err(syn::Error::new(t.span(), "an input port is an argument `name: &Type`"));
        };
        ports.push((id.ident.clone(), r.elem.clone()));
    }
    let results: Vec<Type> = match output_type(&run.sig.output) {
        Ok(t) => match syn::parse2::<Type>(t)? {
            Type::Tuple(tuple) if names.len() > 1 => tuple.elems.into_iter().collect(),
            ty => vec![ty],
        },
        Err(e) => return Err(e),
    };
    if results.len() != names.len() {
        return Err(syn::Error::new(
            run.sig.output.span(),
            format!("outputs = […] names {} ports, run returns {}", names.len(), results.len()),
        ));
    }
    run.sig.ident = format_ident!("run_ports");
    let inputs = if ports.is_empty() { quote!(()) } else { quote!(#in_name<'a>) };
    let in_decl = if ports.is_empty() {
        quote!()
    } else {
        let (pn, pt): (Vec<_>, Vec<_>) = ports.iter().cloned().unzip();
        quote!(#c::inputs!(#[doc(hidden)] pub #in_name { #(#pn: #pt),* });)
    };
    let pn: Vec<_> = ports.iter().map(|(n, _)| n).collect();
    let unpack = if ports.is_empty() { quote!(let _ = __inputs;) } else { quote!(let #in_name { #(#pn),* } = __inputs;) };
    let (wrap, bind) = if names.len() == 1 {
        let n = &names[0];
        (quote!(#out_name { #n: __result }), quote!(__result))
    } else {
        (quote!(#out_name { #(#names),* }), quote!((#(#names),*)))
    };
    Ok(quote! {
        #in_decl
        #c::outputs!(#[doc(hidden)] pub #out_name { #(#names: #results),* });
        impl #c::Node for #self_ty {
            #head
            type Inputs<'a> = #inputs;
            type Outputs = #out_name;
            fn run(&self, __inputs: Self::Inputs<'_>, __cx: &#c::RunCtx) -> ::core::result::Result<Self::Outputs, #c::NodeError> {
                #unpack
                self.run_ports(#(#pn,)* __cx).map(|#bind| #wrap)
            }
            #(#trait_fns)*
        }
        impl #self_ty {
            #run
        }
        #rest
    })
}

/// `()` stays `()`; `In`, `In<'_>` or `In<'x>` becomes `In<'a>`.
fn input_type(ty: &Type) -> syn::Result<Tokens> {
    match ty {
        Type::Tuple(t) if t.elems.is_empty() => Ok(quote!(())),
        Type::Path(p) => {
            let mut p = p.clone();
            let last = p.path.segments.last_mut().unwrap();
            last.arguments = PathArguments::None;
            Ok(quote!(#p<'a>))
        }
        _ => Err(syn::Error::new(ty.span(), "run's inputs are `()` or a struct declared with `inputs!`")),
    }
}

/// `Result<Out, NodeError>` → `Out`.
fn output_type(ret: &ReturnType) -> syn::Result<Tokens> {
    if let ReturnType::Type(_, ty) = ret {
        if let Type::Path(p) = ty.as_ref() {
            if let Some(PathArguments::AngleBracketed(a)) = p.path.segments.last().map(|s| &s.arguments) {
                if let Some(GenericArgument::Type(t)) = a.args.first() {
                    return Ok(quote!(#t));
                }
            }
        }
    }
    Err(syn::Error::new(ret.span(), "run returns Result<Outputs, NodeError>"))
}
