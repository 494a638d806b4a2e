"""hd_twin: the physics-informed LSTM digital twin of the harmonic drive (digital-twin core).

Public surface (heavy modules import torch / onnxruntime lazily):

* :mod:`hd_twin.physics` -- ``TwinParams`` (SI, YAML), the three-body residuals
  ``residuals`` (r1..r4), ``closure_forces``, ``input_friction``, ``q_res``,
  ``quasi_static_Q_red``; one place per equation, numpy or torch.
* :mod:`hd_twin.data` -- ``mission_inputs`` (the raw input matrix shared by
  batch and node), ``features``, ``preprocess``, ``split_missions``.
* :mod:`hd_twin.model` -- ``TwinLSTM``, ``LambdaC``, ``PINN`` (composite loss).
* :mod:`hd_twin.train` -- presets, ``train_twin``, ``load_pinn``, ``eval_model``.
* :mod:`hd_twin.export` -- ``export_onnx``; :mod:`hd_twin.runtime` --
  ``StreamingTwin`` (ONNX Runtime, carried LSTM state).
* :mod:`hd_twin.tune` -- Optuna TPE search; :mod:`hd_twin.ablation` -- PINN vs
  lambda_c = 0 out of the training range.
* :mod:`hd_twin.terms` -- discovery's extra terms (ground engineer).
"""
