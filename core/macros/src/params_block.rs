//! `params! { … }`: a node's parameter struct with each parameter on one line.
//!
//! A parameter is written the way Rust's default field values are (`name: Type = default`),
//! followed by the `#[param]` keys it needs and a semicolon:
//!
//! ```text
//! params! {
//!     /// The node's doc comment (the editor tooltip).
//!     pub struct Blur {
//!         /// standard deviation
//!         pub sigma: f32 = 2.0, range = 0.0..=64.0, unit = "px", test = 1.0;
//!         pub paths: PathCounts, flatten;
//!     }
//! }
//! ```
//!
//! The block becomes the same struct with `#[derive(Params)]` and one `#[param(…)]` per field,
//! so both spellings declare identical schemas and share one checker; the derive's messages
//! point at the keys as written here.

use proc_macro2::{TokenStream as Tokens, TokenTree};
use quote::quote;
use syn::{
    parse::{Parse, ParseStream},
    token, Attribute, Expr, Ident, Token, Type, Visibility,
};

struct Field {
    attrs: Vec<Attribute>,
    vis: Visibility,
    ident: Ident,
    ty: Type,
    default: Option<Expr>,
    keys: Tokens,
}

pub struct Block {
    attrs: Vec<Attribute>,
    vis: Visibility,
    ident: Ident,
    /// `None` for a unit struct.
    fields: Option<Vec<Field>>,
}

impl Parse for Field {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        let attrs = input.call(Attribute::parse_outer)?;
        let vis = input.parse()?;
        let ident = input.parse()?;
        input.parse::<Token![:]>()?;
        let ty = input.parse()?;
        let default = if input.parse::<Option<Token![=]>>()?.is_some() { Some(input.parse()?) } else { None };
        // The remaining `#[param]` keys, as written, up to the semicolon.
        let mut keys = Tokens::new();
        if input.parse::<Option<Token![,]>>()?.is_some() {
            while !input.is_empty() && !input.peek(Token![;]) {
                keys.extend([input.parse::<TokenTree>()?]);
            }
        }
        if !input.is_empty() {
            input.parse::<Token![;]>().map_err(|e| syn::Error::new(e.span(), "a parameter ends with `;`"))?;
        }
        Ok(Field { attrs, vis, ident, ty, default, keys })
    }
}

impl Parse for Block {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        let attrs = input.call(Attribute::parse_outer)?;
        let vis = input.parse()?;
        input.parse::<Token![struct]>()?;
        let ident = input.parse()?;
        if input.parse::<Option<Token![;]>>()?.is_some() {
            return Ok(Block { attrs, vis, ident, fields: None });
        }
        let body;
        syn::braced!(body in input);
        let mut fields = Vec::new();
        while !body.is_empty() {
            fields.push(body.parse()?);
        }
        if !input.is_empty() {
            return Err(input.error("params! holds one struct"));
        }
        Ok(Block { attrs, vis, ident, fields: Some(fields) })
    }
}

/// The struct as `derive(Params)` takes it.
pub fn expand(block: Block) -> Tokens {
    let Block { attrs, vis, ident, fields } = block;
    let c = quote!(::relume_core);
    let Some(fields) = fields else {
        return quote!(#(#attrs)* #[derive(#c::Params)] #vis struct #ident;);
    };
    let fields = fields.into_iter().map(|f| {
        let Field { attrs, vis, ident, ty, default, keys } = f;
        let comma = (!keys.is_empty()).then(token::Comma::default);
        let param = match default {
            Some(d) => quote!(#[param(default = #d #comma #keys)]),
            None if keys.is_empty() => quote!(),
            None => quote!(#[param(#keys)]),
        };
        quote!(#(#attrs)* #param #vis #ident: #ty)
    });
    quote!(#(#attrs)* #[derive(#c::Params)] #vis struct #ident { #(#fields),* })
}
