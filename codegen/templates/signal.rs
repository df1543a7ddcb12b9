{#- The statements for one signal of a message, spelled out from its typed parts
    (codegen/src/render/codec/signal.rs). Imported by can.rs. -#}

{%- macro raw_from_bits(s, bits) -%}
{%- match s.raw -%}
{%- when RawCodec::F32 -%} f32::from_bits({{ bits }} as u32)
{%- when RawCodec::F64 -%} f64::from_bits({{ bits }})
{%- when RawCodec::Signed { len, narrow } -%}
bits::sign_extend({{ bits }}, {{ len }}){% if let Some(ty) = narrow %} as {{ ty }}{% endif %}
{%- when RawCodec::Unsigned64 -%} {{ bits }}
{%- when RawCodec::Unsigned { ty } -%} {{ bits }} as {{ ty }}
{%- endmatch -%}
{%- endmacro -%}

{%- macro bits_from_raw(s, from_self) -%}
{%- match s.raw -%}
{%- when RawCodec::F32 -%} u64::from(Self::{{ s.stem }}_to_raw({% if from_self %}self.{{ s.field }}{% else %}v{% endif %})?.to_bits())
{%- when RawCodec::F64 -%} Self::{{ s.stem }}_to_raw({% if from_self %}self.{{ s.field }}{% else %}v{% endif %})?.to_bits()
{%- when RawCodec::Signed { .. } -%} Self::{{ s.stem }}_to_raw({% if from_self %}self.{{ s.field }}{% else %}v{% endif %})? as u64
{%- when RawCodec::Unsigned64 -%} Self::{{ s.stem }}_to_raw({% if from_self %}self.{{ s.field }}{% else %}v{% endif %})?
{%- when RawCodec::Unsigned { .. } -%} u64::from(Self::{{ s.stem }}_to_raw({% if from_self %}self.{{ s.field }}{% else %}v{% endif %})?)
{%- endmatch -%}
{%- endmacro -%}

{%- macro write(s, value) -%}
bits::write_{{ s.placement.order }}(out, {{ s.placement.start }}, {{ s.placement.len }}, {{ value }});
{%- endmacro -%}

{%- macro condition(c) -%}
matches!({{ c.selector }}, {% if c.selector_optional %}Some({{ c.patterns() }}){% else %}{{ c.patterns() }}{% endif %})
{%- endmacro -%}

{#- Around the raw value, what turns it into what the local holds: the physical value, or for
    an enum with `raw_enum` the raw number in the enum's representation (what a visitor gets). -#}
{%- macro conv_open(s, raw_enum) -%}
{%- match s.conversion -%}
{%- when Conversion::Enum { widen, .. } -%}
{%- if raw_enum -%}
{%- if let Some(repr) = widen -%} {{ repr }}::from( {%- endif -%}
{%- else -%} Self::{{ s.stem }}_from_raw(
{%- endif -%}
{%- else -%} Self::{{ s.stem }}_from_raw(
{%- endmatch -%}
{%- endmacro -%}

{%- macro conv_close(s, raw_enum) -%}
{%- match s.conversion -%}
{%- when Conversion::Enum { widen, .. } -%}
{%- if !raw_enum || widen.is_some() -%} ) {%- endif -%}
{%- else -%} )
{%- endmatch -%}
{%- endmacro -%}

{#- Statements binding the field (and, for a multiplexor, its bits) from `data`. -#}
{%- macro decode(s, raw_enum) -%}
{%- match s.presence -%}
{%- when Presence::Always -%}
{%- if s.is_multiplexor %}
        let {{ s.stem }}_bits = {{ s.read_expr() }};
        let {{ s.field }} = {% call conv_open(s, raw_enum) %}{% endcall %}{% call raw_from_bits(s, s.bits_local()) %}{% endcall %}{% call conv_close(s, raw_enum) %}{% endcall %};
{%- else %}
        let {{ s.field }} = {% call conv_open(s, raw_enum) %}{% endcall %}{% call raw_from_bits(s, s.read_expr()) %}{% endcall %}{% call conv_close(s, raw_enum) %}{% endcall %};
{%- endif -%}
{%- when Presence::When(c) -%}
{%- if s.is_multiplexor %}
        let {{ s.stem }}_bits = if {% call condition(c) %}{% endcall %} { Some({{ s.read_expr() }}) } else { None };
        let {{ s.field }} = {{ s.stem }}_bits.map(|bits| {% call conv_open(s, raw_enum) %}{% endcall %}{% call raw_from_bits(s, "bits") %}{% endcall %}{% call conv_close(s, raw_enum) %}{% endcall %});
{%- else %}
        let {{ s.field }} = if {% call condition(c) %}{% endcall %} {
            Some({% call conv_open(s, raw_enum) %}{% endcall %}{% call raw_from_bits(s, s.read_expr()) %}{% endcall %}{% call conv_close(s, raw_enum) %}{% endcall %})
        } else {
            None
        };
{%- endif -%}
{%- endmatch -%}
{%- endmacro -%}

{#- Statements writing the field into `out`; a multiplexed field must be present exactly when
    its multiplexor selects it. -#}
{%- macro encode(s) -%}
{%- match s.presence -%}
{%- when Presence::Always -%}
{%- if s.is_multiplexor %}
        let {{ s.stem }}_bits = {% call bits_from_raw(s, true) %}{% endcall %};
        {% call write(s, s.bits_local()) %}{% endcall %}
{%- else %}
        bits::write_{{ s.placement.order }}(out, {{ s.placement.start }}, {{ s.placement.len }}, {% call bits_from_raw(s, true) %}{% endcall %});
{%- endif -%}
{%- when Presence::When(c) -%}
{%- if s.is_multiplexor %}
        let {{ s.stem }}_bits = {% call checked(s, c) %}{% endcall %};
        if let Some(bits) = {{ s.stem }}_bits {
            {% call write(s, "bits") %}{% endcall %}
        }
{%- else %}
        if let Some(bits) = {% call checked(s, c) %}{% endcall %} {
            {% call write(s, "bits") %}{% endcall %}
        }
{%- endif -%}
{%- endmatch -%}
{%- endmacro -%}

{%- macro checked(s, c) -%}
match ({% call condition(c) %}{% endcall %}, self.{{ s.field }}) {
            (true, Some(v)) => Some({% call bits_from_raw(s, false) %}{% endcall %}),
            (false, None) => None,
            (true, None) => return Err(EncodeError::MissingSignal { message: {{ s.message }}, signal: {{ s.name }} }),
            (false, Some(_)) => return Err(EncodeError::NotSelected { message: {{ s.message }}, signal: {{ s.name }} }),
        }
{%- endmacro -%}

{%- macro value(s) -%}
{%- match s.value -%}
{%- when ValueKind::Enum { .. } -%} Value::from(v.into_raw())
{%- else -%} Value::from(v)
{%- endmatch -%}
{%- endmacro -%}

{%- macro label(s) -%}
{%- match s.value -%}
{%- when ValueKind::Enum { .. } -%} v.label()
{%- else -%}
{%- if s.named.is_some() -%} Self::{{ s.stem }}_label(v)
{%- else -%} None
{%- endif -%}
{%- endmatch -%}
{%- endmacro -%}

{#- The visitor call for the field's value, when present. -#}
{%- macro visit(m, s) -%}
{%- if s.optional() %}
        if let Some(v) = self.{{ s.field }} {
            visitor.signal(&{{ m.meta_static }}[{{ s.index }}], {% call value(s) %}{% endcall %}, {% call label(s) %}{% endcall %});
        }
{%- else %}
        let v = self.{{ s.field }};
        visitor.signal(&{{ m.meta_static }}[{{ s.index }}], {% call value(s) %}{% endcall %}, {% call label(s) %}{% endcall %});
{%- endif -%}
{%- endmacro -%}

{#- The label of the value `v` (a local bound by `decode(s, true)`, or its contents). -#}
{%- macro local_label(s, v) -%}
{%- match s.value -%}
{%- when ValueKind::Enum { .. } -%} {{ s.phys_ty }}::from_raw({{ v }}).label()
{%- else -%}
{%- if s.named.is_some() -%} Self::{{ s.stem }}_label({{ v }})
{%- else -%} None
{%- endif -%}
{%- endmatch -%}
{%- endmacro -%}

{#- The visitor call for a local bound by `decode(s, true)`, when present. The local is used
    by name (not bound to `v`, which could be another signal's local). -#}
{%- macro visit_local(m, s) -%}
{%- if s.optional() %}
        if let Some(v) = {{ s.field }} {
            visitor.signal(&{{ m.meta_static }}[{{ s.index }}], Value::from(v), {% call local_label(s, "v") %}{% endcall %});
        }
{%- else %}
        visitor.signal(&{{ m.meta_static }}[{{ s.index }}], Value::from({{ s.field }}), {% call local_label(s, s.field) %}{% endcall %});
{%- endif -%}
{%- endmacro -%}

{#- A source's `Value` `v` as the field's type, `None` when it does not fit. -#}
{%- macro from_value(s) -%}
{%- match s.value -%}
{%- when ValueKind::Bool -%} v.to_bool()
{%- when ValueKind::Int { ty } -%} v.to_int::<{{ ty }}>()
{%- when ValueKind::F32 -%} Some(v.to_f32())
{%- when ValueKind::F64 -%} Some(v.to_f64())
{%- when ValueKind::Enum { repr } -%} v.to_int::<{{ repr }}>().map({{ s.phys_ty }}::from_raw)
{%- endmatch -%}
{%- endmacro -%}

{#- The field's initializer in `from_signals`. -#}
{%- macro from_signals(m, s) -%}
{%- if s.optional() -%}
match source.value(&{{ m.meta_static }}[{{ s.index }}]) {
                Some(v) => Some({% call from_value(s) %}{% endcall %}.ok_or(EncodeError::InvalidValue { message: {{ s.message }}, signal: {{ s.name }} })?),
                None => None,
            }
{%- else -%}
{
                let v = source.value(&{{ m.meta_static }}[{{ s.index }}]).ok_or(EncodeError::MissingSignal { message: {{ s.message }}, signal: {{ s.name }} })?;
                {% call from_value(s) %}{% endcall %}.ok_or(EncodeError::InvalidValue { message: {{ s.message }}, signal: {{ s.name }} })?
            }
{%- endif -%}
{%- endmacro -%}

{%- macro out_of_range(s) -%}
EncodeError::OutOfRange { message: {{ s.message }}, signal: {{ s.name }} }
{%- endmacro -%}

{#- `Ok(raw)` for an integer raw value, checked against the signal's width when narrower than
    its type; `value` is bound to `raw` first unless it already is `raw`. -#}
{%- macro fit(s, fit, value) -%}
{%- match fit -%}
{%- when Fit::Full %}
        Ok({{ value }})
{%- when Fit::Range { lo, hi } -%}
{%- if value != "raw" %}
        let raw = {{ value }};
{%- endif %}
        if ({{ lo }}..={{ hi }}).contains(&raw) { Ok(raw) } else { Err({% call out_of_range(s) %}{% endcall %}) }
{%- endmatch -%}
{%- endmacro -%}

{#- Body of `<field>_from_raw(raw)`. -#}
{%- macro from_raw(s) -%}
{%- match s.conversion -%}
{%- when Conversion::Bool -%} raw != 0
{%- when Conversion::Enum { widen, .. } -%}
{%- if let Some(repr) = widen -%} {{ s.phys_ty }}::from_raw({{ repr }}::from(raw))
{%- else -%} {{ s.phys_ty }}::from_raw(raw)
{%- endif -%}
{%- when Conversion::Int { convert, .. } -%}
{%- if convert -%} {{ s.phys_ty }}::from(raw) {%- else -%} raw {%- endif -%}
{%- when Conversion::IntScaled { scaling, .. } -%}
({{ scaling.arith }}::from(raw){% if scaling.factor != 1 %} * {{ scaling.factor }}{% endif %}{{ scaling.offset_term() }}) as {{ s.phys_ty }}
{%- when Conversion::Float { scaling, wire } -%}
{%- match wire -%}
{%- when FloatWire::F32Plain -%} raw
{%- when FloatWire::F32Scaled -%} ({{ scaling.apply("f64::from(raw)") }}) as f32
{%- when FloatWire::F32Wide -%} {{ scaling.apply("f64::from(raw)") }}
{%- when FloatWire::F64 -%} {{ scaling.apply("raw") }}
{%- endmatch -%}
{%- when Conversion::Quantized { scaling, phys_f32, raw_to_f64, .. } -%}
{%- if phys_f32 -%} ({{ scaling.apply(raw_to_f64.of("raw")) }}) as f32
{%- else -%} {{ scaling.apply(raw_to_f64.of("raw")) }}
{%- endif -%}
{%- endmatch -%}
{%- endmacro -%}

{#- Body of `<field>_to_raw(v)`: the range check, then the conversion. -#}
{%- macro to_raw(s) -%}
{%- if let Some(check) = s.range -%}
{%- match check.value -%}
{%- when PhysAsF64::Bool %}
        runtime::check_range(f64::from(u8::from(v)), {{ check.min }}, {{ check.max }}, {{ check.tolerance }}, {{ s.message }}, {{ s.name }})?;
{%- when PhysAsF64::Number(to_f64) %}
        runtime::check_range({{ to_f64.of("v") }}, {{ check.min }}, {{ check.max }}, {{ check.tolerance }}, {{ s.message }}, {{ s.name }})?;
{%- when PhysAsF64::NamedNumber(to_f64) %}
        if Self::{{ s.stem }}_label(v).is_none() {
            runtime::check_range({{ to_f64.of("v") }}, {{ check.min }}, {{ check.max }}, {{ check.tolerance }}, {{ s.message }}, {{ s.name }})?;
        }
{%- when PhysAsF64::UnknownEnum { scaling } %}
        if let {{ s.phys_ty }}::Unknown(raw) = v {
            runtime::check_range({{ scaling.apply("raw as f64") }}, {{ check.min }}, {{ check.max }}, {{ check.tolerance }}, {{ s.message }}, {{ s.name }})?;
        }
{%- endmatch -%}
{%- endif -%}
{%- match s.conversion -%}
{%- when Conversion::Bool %}
        Ok(u8::from(v))
{%- when Conversion::Enum { widen, fit } -%}
{%- if widen.is_some() %}
        let raw = {{ s.raw_ty }}::try_from(v.into_raw()).map_err(|_| {% call out_of_range(s) %}{% endcall %})?;
        {%- call fit(s, fit, "raw") -%}{% endcall %}
{%- else -%}
        {%- call fit(s, fit, "v.into_raw()") -%}{% endcall %}
{%- endif -%}
{%- when Conversion::Int { convert, fit } -%}
{%- if convert %}
        let raw = {{ s.raw_ty }}::try_from(v).map_err(|_| {% call out_of_range(s) %}{% endcall %})?;
        {%- call fit(s, fit, "raw") -%}{% endcall %}
{%- else -%}
        {%- call fit(s, fit, "v") -%}{% endcall %}
{%- endif -%}
{%- when Conversion::IntScaled { scaling, fit } -%}
{%- if scaling.factor == 1 %}
        let raw = {{ scaling.arith }}::from(v){{ scaling.minus_offset() }};
{%- else %}
        let raw = runtime::div_round(i128::from(v){{ scaling.minus_offset() }}, {{ scaling.factor }});
{%- endif %}
        let raw = {{ s.raw_ty }}::try_from(raw).map_err(|_| {% call out_of_range(s) %}{% endcall %})?;
        {%- call fit(s, fit, "raw") -%}{% endcall %}
{%- when Conversion::Float { scaling, wire } -%}
{%- match wire -%}
{%- when FloatWire::F32Plain %}
        Ok(v)
{%- when FloatWire::F32Scaled %}
        Ok(({{ scaling.invert("f64::from(v)") }}) as f32)
{%- when FloatWire::F32Wide %}
        Ok(({{ scaling.invert("v") }}) as f32)
{%- when FloatWire::F64 %}
        Ok({{ scaling.invert("v") }})
{%- endmatch -%}
{%- when Conversion::Quantized { scaling, phys_to_f64, lo, hi, bounded, .. } %}
{%- if let Some(b) = bounded %}
{%- if let Some((bits_lo, bits_hi)) = b.bits %}
        // The range check bounds the value for the integer rounding (shown when generated).
        let raw = runtime::{{ b.round }}({{ scaling.invert(phys_to_f64.of("v")) }});
        if ({{ bits_lo }}..{{ bits_hi }}).contains(&raw) { Ok(raw as {{ s.raw_ty }}) } else { Err({% call out_of_range(s) %}{% endcall %}) }
{%- else %}
        // The range check keeps the raw value inside the signal's bits (shown when generated).
        Ok(runtime::{{ b.round }}({{ scaling.invert(phys_to_f64.of("v")) }}) as {{ s.raw_ty }})
{%- endif %}
{%- else %}
        let raw = runtime::round({{ scaling.invert(phys_to_f64.of("v")) }});
        if ({{ lo }}..{{ hi }}).contains(&raw) { Ok(raw as {{ s.raw_ty }}) } else { Err({% call out_of_range(s) %}{% endcall %}) }
{%- endif -%}
{%- endmatch -%}
{%- endmacro -%}
