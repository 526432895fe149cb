//! `#[derive(DescribedParameters)]` on a node's parameter struct: each field becomes one ROS 2
//! parameter of the node, named by its serde key (`#[serde(rename = "...")]` honoured), its
//! description the field's doc comment, its type the field's Rust type
//! (`node_shell::parameters::ParameterKind`), read-only unless marked
//! `#[parameter(writable)]`: a key the node's core applies while it runs. The node shell serves
//! them through the standard parameter services (`node_shell::parameters`).

use proc_macro::TokenStream;
use quote::quote;
use syn::{Data, DeriveInput, Expr, Fields, Lit, Meta, parse_macro_input};

#[proc_macro_derive(DescribedParameters, attributes(parameter))]
pub fn derive_described_parameters(input: TokenStream) -> TokenStream {
    let input = parse_macro_input!(input as DeriveInput);
    match expand(&input) {
        Ok(tokens) => tokens.into(),
        Err(e) => e.to_compile_error().into(),
    }
}

fn expand(input: &DeriveInput) -> syn::Result<proc_macro2::TokenStream> {
    let Data::Struct(data) = &input.data else {
        return Err(syn::Error::new_spanned(
            input,
            "DescribedParameters: a struct of named fields only",
        ));
    };
    let Fields::Named(fields) = &data.fields else {
        return Err(syn::Error::new_spanned(
            input,
            "DescribedParameters: a struct of named fields only",
        ));
    };
    let mut entries = Vec::new();
    for field in &fields.named {
        let ident = field.ident.as_ref().expect("named field");
        let mut key = ident.to_string();
        let mut doc = Vec::new();
        let mut writable = false;
        let mut hidden = false;
        for attr in &field.attrs {
            if attr.path().is_ident("doc") {
                if let Meta::NameValue(nv) = &attr.meta
                    && let Expr::Lit(lit) = &nv.value
                    && let Lit::Str(s) = &lit.lit
                {
                    doc.push(s.value().trim().to_string());
                }
            } else if attr.path().is_ident("serde") {
                attr.parse_nested_meta(|meta| {
                    if meta.path.is_ident("rename") {
                        let value: syn::LitStr = meta.value()?.parse()?;
                        key = value.value();
                    } else if meta.input.peek(syn::Token![=]) {
                        // Any other `name = value` (default = "...", with = "..."): skip it.
                        let _: Expr = meta.value()?.parse()?;
                    }
                    Ok(())
                })?;
            } else if attr.path().is_ident("parameter") {
                attr.parse_nested_meta(|meta| {
                    if meta.path.is_ident("writable") {
                        writable = true;
                        Ok(())
                    } else if meta.path.is_ident("hidden") {
                        hidden = true;
                        Ok(())
                    } else {
                        Err(meta.error("expected #[parameter(writable)] or #[parameter(hidden)]"))
                    }
                })?;
            }
        }
        if doc.is_empty() {
            return Err(syn::Error::new_spanned(
                ident,
                "DescribedParameters: every parameter needs a doc comment (its description)",
            ));
        }
        // Doc lines joined as rustdoc joins a paragraph's lines.
        let description = doc
            .iter()
            .filter(|l| !l.is_empty())
            .cloned()
            .collect::<Vec<_>>()
            .join(" ");
        let ty = &field.ty;
        entries.push(quote! {
            ::node_shell::parameters::Declared {
                name: #key,
                description: #description,
                kind: <#ty as ::node_shell::parameters::ParameterKind>::KIND,
                writable: #writable,
                hidden: #hidden,
            }
        });
    }
    let name = &input.ident;
    let (impl_generics, ty_generics, where_clause) = input.generics.split_for_impl();
    Ok(quote! {
        impl #impl_generics ::node_shell::parameters::DescribedParameters for #name #ty_generics
            #where_clause
        {
            fn declared() -> ::std::vec::Vec<::node_shell::parameters::Declared> {
                ::std::vec![ #( #entries ),* ]
            }
        }
    })
}
