{#- The statements for one telemetry field, spelled out from its typed parts
    (codegen/src/render/telemetry/field.rs). Imported by telemetry.rs. -#}

{#- Body of `<field>_from_raw(raw)`. -#}
{%- macro from_raw(f) -%}
{%- match f.conversion -%}
{%- when FieldConversion::Identity -%} raw
{%- when FieldConversion::Enum -%} {{ f.phys_ty }}::from_raw(raw)
{%- when FieldConversion::IntScaled { scaling, .. } -%}
({{ scaling.arith }}::from(raw){% if scaling.factor != 1 %} * {{ scaling.factor }}{% endif %}{{ scaling.offset_term() }}) as {{ f.phys_ty }}
{%- when FieldConversion::Float { scaling, phys_f32, .. } | FieldConversion::Quantized { scaling, phys_f32, .. } -%}
{%- if phys_f32 -%} ({{ scaling.apply("f64::from(raw)") }}) as f32
{%- else -%} {{ scaling.apply("f64::from(raw)") }}
{%- endif -%}
{%- endmatch -%}
{%- endmacro -%}

{#- Body of `<field>_to_raw(v)`: the wire value and whether it was saturated. -#}
{%- macro to_raw(f) -%}
{%- match f.conversion -%}
{%- when FieldConversion::Identity %}
        (v, false)
{%- when FieldConversion::Enum %}
        (v.into_raw(), false)
{%- when FieldConversion::IntScaled { scaling, lo, hi } -%}
{%- if scaling.factor == 1 %}
        let raw = {{ scaling.arith }}::from(v){{ scaling.minus_offset() }};
{%- else %}
        let raw = runtime::div_round(i128::from(v){{ scaling.minus_offset() }}, {{ scaling.factor }});
{%- endif %}
        let clamped = raw.clamp({{ lo }}, {{ hi }});
        (clamped as {{ f.wire_ty }}, clamped != raw)
{%- when FieldConversion::Float { scaling, phys_to_f64, .. } %}
        (({{ scaling.invert(phys_to_f64.of("v")) }}) as f32, false)
{%- when FieldConversion::Quantized { scaling, phys_to_f64, lo, hi, .. } %}
        let raw = runtime::round({{ scaling.invert(phys_to_f64.of("v")) }});
        if raw.is_nan() {
            return (0, true);
        }
        let clamped = raw.clamp({{ lo }}, {{ hi }});
        (clamped as {{ f.wire_ty }}, clamped != raw)
{%- endmatch -%}
{%- endmacro -%}

{#- Packs the field into `out`, counting a saturated value. -#}
{%- macro pack(f) %}
        let (raw, clamped) = Self::{{ f.name }}_to_raw(self.{{ f.name }});
        saturated += u8::from(clamped);
{%- match f.placement -%}
{%- when FieldPlacement::Bytes { at } %}
        runtime::put(out, {{ at }}, &raw.to_le_bytes());
{%- when FieldPlacement::Flag { byte, bit, .. } %}
        if raw {
            if let Some(b) = out.get_mut({{ byte }}) {
                *b |= 1 << {{ bit }};
            }
        }
{%- endmatch -%}
{%- endmacro -%}

{%- macro unpack(f) -%}
{%- match f.placement -%}
{%- when FieldPlacement::Bytes { at } -%}
Self::{{ f.name }}_from_raw({{ f.wire_ty }}::from_le_bytes(runtime::take(data, {{ at }})))
{%- when FieldPlacement::Flag { byte, bit, .. } -%}
Self::{{ f.name }}_from_raw(data.get({{ byte }}).is_some_and(|b| b & (1 << {{ bit }}) != 0))
{%- endmatch -%}
{%- endmacro -%}

{%- macro default(f) -%}
{%- match f.default -%}
{%- when FieldDefault::False -%} false
{%- when FieldDefault::Zero -%} 0
{%- when FieldDefault::ZeroFloat -%} 0.0
{%- when FieldDefault::RawZero -%} {{ f.phys_ty }}::from_raw(0)
{%- endmatch -%}
{%- endmacro -%}

{%- macro visit(f) %}
        let v = self.{{ f.name }};
{%- if f.is_enum %}
        visitor.signal(&TELEMETRY_FIELDS[{{ f.index }}], Value::from(v.into_raw()), v.label());
{%- else %}
        visitor.signal(&TELEMETRY_FIELDS[{{ f.index }}], Value::from(v), None);
{%- endif -%}
{%- endmacro -%}

{%- macro display(d) -%}
    FieldDisplay {
        group: {{ d.group }},
        label: {{ d.label }},
        warn: {{ d.warn }},
        critical: {{ d.critical }},
        warn_below: {{ d.warn_below }},
        critical_below: {{ d.critical_below }},
        mirrors: {{ d.mirrors }},
    }
{%- endmacro -%}

{%- macro mirror(copy) -%}
{%- if copy.optional %}
                if let Some(v) = m.{{ copy.signal }} {
                    self.{{ copy.field }} = v{% if let Some(ty) = copy.cast %} as {{ ty }}{% endif %};
                }
{%- else %}
                self.{{ copy.field }} = m.{{ copy.signal }}{% if let Some(ty) = copy.cast %} as {{ ty }}{% endif %};
{%- endif -%}
{%- endmacro -%}
