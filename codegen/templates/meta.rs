{#- The `SignalMeta` literal of a CAN signal or a telemetry field (a `MetaView`). -#}
{%- macro signal_meta(meta) -%}
    SignalMeta {
        name: {{ meta.name }},
        index: {{ meta.index }},
        unit: {{ meta.unit }},
        comment: {{ meta.comment }},
        start_bit: {{ meta.start_bit }},
        len: {{ meta.len }},
        byte_order: ByteOrder::{{ meta.byte_order }},
        signed: {{ meta.signed }},
        factor: {{ meta.factor }},
        offset: {{ meta.offset }},
        min: {{ meta.min }},
        max: {{ meta.max }},
        labels: &[{% for (value, label) in meta.labels %}({{ value }}, {{ label }}){% if !loop.last %}, {% endif %}{% endfor %}],
        multiplexed: {{ meta.multiplexed }},
    }
{%- endmacro -%}
