"""The hostile /hd/twin/update payloads of issue 13 (text, expected field or phrase in the refusal)."""

HOSTILE_UPDATES: list[tuple[str, str, str]] = [
    ("effects_int", '{"effects": 5}', "effects"),
    ("notes_int", '{"params": {"notes": 5}}', "params.notes"),
    ("deep_json", '{"normalisation": ' + "[" * 200_000 + "]" * 200_000 + "}", "nested"),
    ("zero_inertias", '{"params": {"J_WG": 0, "J_rotor": 0, "J_CS": 0, "m_FSx": 0, "m_FSy": 0}}', "inertia"),
    ("N_bool", '{"params": {"N": true}}', "params.N"),
    ("nan_normalisation", '{"normalisation": {"mean": [1.0, NaN]}}', "NaN"),
    ("inf_degradation", '{"degradation_law": {"name": "archard", "k_wear": Infinity}}', "Infinity"),
    ("huge_number_degradation", '{"degradation_law": {"name": "archard", "k_wear": 1e999}}', "degradation_law.k_wear"),
    ("model_dir_etc", '{"model_dir": "/etc"}', "model_dir"),
    ("model_dir_dotdot", '{"model_dir": "../../../../etc/passwd"}', "model_dir"),
    ("updated_by_10MB", '{"updated_by": "' + "x" * 10_000_000 + '"}', "cap"),
    ("updated_by_long", '{"updated_by": "' + "x" * 1000 + '"}', "updated_by"),
    ("thresholds_not_mapping", '{"thresholds": {"EMA-1": 5}}', "thresholds.EMA-1"),
    ("thresholds_bad_id", '{"thresholds": {"../../x": {"stiffness": {"mu": 0}}}}', "thresholds"),
    ("references_list", '{"references": []}', "references"),
    ("unknown_key", '{"evil": 1}', "unknown key"),
    ("not_json", "{not json", "not valid JSON"),
    ("json_list", "[1, 2, 3]", "JSON object"),
    ("params_string", '{"params": "N=50"}', "params"),
    ("params_unknown", '{"params": {"__class__": 1}}', "params.__class__"),
]
