"""The physics-informed LSTM: network, learnable physics weight, composite loss.

Loss (paper eq. 1-4)::

    L_tot = exp(-s_d) L_d + s_d + ramp(epoch) * [exp(-s_c) L_c + nu s_c]   (uncertainty form)
    lambda_c = exp(s_d - s_c)
    L_d   = mean over valid samples of ((Q_red_hat - Q_red) / sigma_Q)^2
    L_c   = 1/4 sum_j mean_t (r_j / s_j)^2

* ``L_d`` is the paper's MSE of Q_red, made dimensionless by the training
  standard deviation sigma_Q (so that it is comparable with L_c); samples with
  NaN Q_red (or any NaN input) and the first ``washout`` samples of each window
  (the LSTM starts from a zero state) are masked out.
* ``r_j`` are the residuals of :func:`hd_twin.physics.residuals`, evaluated on
  the interior samples (second differences of the latent states need both
  neighbours). ``s_j`` is either the running RMS of r_j (adaptive scaling:
  exponential moving average, momentum ``scale_momentum``, detached; updated
  during the ramp, then frozen so that L_c can still decrease) or the
  fixed characteristic magnitude of :func:`hd_twin.physics.residual_scales`.
  ``L_c_ref`` (always reported) uses the fixed magnitudes, so that curves are
  comparable across epochs whatever the scaling.
* ``lambda_c`` in the two-task uncertainty form (:class:`LambdaC`): at its
  stationary point lambda_c = nu L_d / L_c > 0 (nu = initial lambda_c), so it
  adapts but cannot collapse to zero; ``mode="fixed"`` keeps lambda_c constant
  (``lambda_c = 0`` is the pure-data ablation).
* ``ramp`` rises linearly from 0 to 1 over ``ramp_epochs`` (0 = off).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from . import physics as ph


class TwinLSTM(nn.Module):
    """Unidirectional stacked LSTM + linear head: features [B, T, n_in] -> outputs [B, T, n_out].

    With ``skip`` a linear map of the current features is added to the head
    (y = W_h h_t + W_x x_t + b): the quasi-static part of the torque (stiffness
    times twist, N times motor torque) is linear in the features, so the LSTM
    only has to learn the dynamic remainder (faster, better-conditioned
    training; plain LSTM when off).
    """

    def __init__(self, n_in: int, n_out: int, hidden: int, layers: int, dropout: float, skip: bool = True):
        super().__init__()
        if layers < 1 or hidden < 1:
            raise ValueError(f"LSTM needs layers >= 1 and hidden >= 1, got {layers}, {hidden}")
        if not 0.0 <= dropout < 1.0:
            raise ValueError(f"dropout must be in [0, 1), got {dropout}")
        self.n_in, self.n_out, self.hidden, self.layers = n_in, n_out, hidden, layers
        self.lstm = nn.LSTM(n_in, hidden, num_layers=layers, batch_first=True,
                            dropout=dropout if layers > 1 else 0.0, bidirectional=False)
        self.head = nn.Linear(hidden, n_out)
        self.skip = nn.Linear(n_in, n_out, bias=False) if skip else None

    def forward(self, x: torch.Tensor, state: tuple[torch.Tensor, torch.Tensor] | None = None):
        z, (h, c) = self.lstm(x, state)
        y = self.head(z)
        if self.skip is not None:
            y = y + self.skip(x)
        return y, (h, c)


class StreamWrapper(nn.Module):
    """ONNX-exportable form: (x [B,T,n_in], h0 [L,B,H], c0 [L,B,H]) -> (y, h_n, c_n)."""

    def __init__(self, net: TwinLSTM):
        super().__init__()
        self.net = net

    def forward(self, x, h0, c0):
        y, (h, c) = self.net(x, (h0, c0))
        return y, h, c


class LambdaC(nn.Module):
    """Physics weight lambda_c; ``mode`` "uncertainty" (learnable, cannot collapse) or "fixed".

    "uncertainty" is the two-task homoscedastic-uncertainty form (Kendall et
    al. 2018) with log-weights s_d, s_c::

        L = exp(-s_d) L_d + s_d + exp(-s_c) L_c + nu s_c,     nu = lambda_c(0)
        lambda_c = exp(-s_c) / exp(-s_d)

    Its stationary point is exp(-s_d) = 1/L_d, exp(-s_c) = nu/L_c, i.e.
    lambda_c = nu L_d / L_c > 0: the weight adapts to the relative progress of
    the two terms and cannot collapse to zero. The effective objective is
    log L_d + nu log L_c, so a relative improvement of the physics is worth nu
    times the same relative improvement of the data fit (scale-free, unlike a
    single learnable weight, which would make the physics a log-barrier that
    keeps trading data accuracy for ever-smaller residuals). s are clamped so
    that each weight stays in [lam_min, lam_max].
    """

    def __init__(self, init: float, mode: str = "uncertainty", lam_min: float = 1e-4, lam_max: float = 1e4):
        super().__init__()
        if mode not in ("uncertainty", "fixed"):
            raise ValueError(f"lambda_c mode must be 'uncertainty' or 'fixed', got {mode!r}")
        if not math.isfinite(init) or init < 0:
            raise ValueError(f"initial lambda_c must be finite and >= 0, got {init}")
        if mode == "uncertainty" and init <= 0:
            raise ValueError("a learnable lambda_c needs a positive initial value (use mode='fixed' for 0)")
        self.mode, self.init = mode, float(init)
        self.lam_min, self.lam_max = float(lam_min), float(lam_max)
        if mode == "uncertainty":
            self.s_d = nn.Parameter(torch.tensor(0.0))
            self.s = nn.Parameter(torch.tensor(-math.log(init), dtype=torch.float32))
        else:
            self.register_buffer("s", torch.tensor(-math.log(init) if init > 0 else float("inf")))

    def _clamped(self, s):
        return s.clamp(-math.log(self.lam_max), -math.log(self.lam_min))

    def value(self) -> torch.Tensor:
        if self.mode == "fixed":
            return torch.tensor(self.init, device=self.s.device)
        return torch.exp(self._clamped(self.s_d) - self._clamped(self.s))

    def total(self, L_d: torch.Tensor, L_c: torch.Tensor | None, ramp: float = 1.0) -> torch.Tensor:
        """The training objective from the data and physics losses (physics part scaled by the ramp)."""
        if self.mode == "fixed":
            return L_d if L_c is None or self.init == 0 else L_d + ramp * self.init * L_c
        s_d = self._clamped(self.s_d)
        out = torch.exp(-s_d) * L_d + s_d
        if L_c is not None:
            s_c = self._clamped(self.s)
            out = out + ramp * (torch.exp(-s_c) * L_c + self.init * s_c)
        return out


@dataclass
class LossConfig:
    lambda_mode: str = "uncertainty"  # "uncertainty" | "fixed"
    lambda_init: float = 8e-2
    adaptive_scaling: bool = True
    scale_momentum: float = 0.95
    ramp_epochs: int = 5  # 0 = no ramp
    washout: int = 16  # samples at the start of each window excluded from every loss term


class ResidualScaler(nn.Module):
    """Running RMS of each residual (buffers, saved with the model)."""

    def __init__(self, fixed: np.ndarray, adaptive: bool, momentum: float):
        super().__init__()
        self.adaptive, self.momentum = adaptive, float(momentum)
        self.register_buffer("fixed", torch.as_tensor(np.asarray(fixed, dtype=np.float32)))
        self.register_buffer("running", torch.as_tensor(np.asarray(fixed, dtype=np.float32)).clone())
        self.register_buffer("initialised", torch.tensor(False))

    def update(self, rms: torch.Tensor) -> None:
        if not self.adaptive:
            return
        rms = rms.detach().clamp_min(1e-12)
        if not bool(self.initialised):
            self.running.copy_(rms)
            self.initialised.fill_(True)
        else:
            self.running.mul_(self.momentum).add_((1 - self.momentum) * rms)

    def scales(self) -> torch.Tensor:
        return self.running if self.adaptive else self.fixed


def ramp_factor(epoch: float, ramp_epochs: int) -> float:
    """Linear ramp 0 -> 1 over ``ramp_epochs`` epochs (epoch counts from 0); 1 when off."""
    if ramp_epochs <= 0:
        return 1.0
    return float(min(1.0, (epoch + 1) / (ramp_epochs + 1)))


def _extra(terms, signals, xp):
    """Sum of discovery's extra terms, or None (hd_twin.terms.evaluate_terms when present)."""
    if not terms:
        return None
    try:
        from .terms import evaluate_terms
    except ImportError as e:  # pragma: no cover - the discovery engineer's module
        raise ValueError(f"model config has extra_terms but hd_twin.terms is not available ({e})") from None
    return evaluate_terms(terms, signals, xp)


def physics_residuals_torch(pred_SI: dict, batch: dict, params: ph.TwinParams, effects, extra_terms=()):
    """r1..r4 [B, T-2] on the interior samples, from SI predictions and batch signals.

    ``pred_SI``: Q_red [N*m], u [m], y [m], each [B, T]. ``batch``: dt [B, 1]
    (s) and the signals theta_m_dd, theta_f_dd, phi, phi_d, omega_m, tau_m,
    temperature, theta_m, theta_f, omega_f, each [B, T].
    """
    dt = batch["dt"]
    Q, u, y = pred_SI["Q_red"], pred_SI["u"], pred_SI["y"]
    mid = slice(1, -1)
    u_d = (u[:, 2:] - u[:, :-2]) / (2 * dt)
    y_d = (y[:, 2:] - y[:, :-2]) / (2 * dt)
    u_dd = (u[:, 2:] - 2 * u[:, 1:-1] + u[:, :-2]) / dt**2
    y_dd = (y[:, 2:] - 2 * y[:, 1:-1] + y[:, :-2]) / dt**2
    g = {k: batch[k][:, mid] for k in ("theta_m_dd", "theta_f_dd", "phi", "phi_d", "omega_m", "tau_m",
                                        "temperature", "theta_m", "theta_f", "omega_f")}
    Qm = Q[:, mid]
    F_b, F_mx, F_my, F_FS = ph.closure_forces(torch, params, effects, u[:, mid], u_d, y[:, mid], y_d,
                                              g["phi"], g["phi_d"], g["omega_m"])
    extra_in = extra_out = None
    if extra_terms:
        sig = dict(g)
        sig["Q_red"] = Qm
        sig["i_q"] = g["tau_m"] / params.k_t
        t_in = [t for t in extra_terms if t.get("signal", "tau_m") == "tau_m"]
        t_out = [t for t in extra_terms if t.get("signal") == "Q_red"]
        extra_in = _extra(t_in, sig, torch)
        extra_out = _extra(t_out, sig, torch)
    Q_res = ph.q_res(torch, params, effects, g["tau_m"], g["omega_m"], g["temperature"], Qm, extra_in)
    x_dd = params.r_b * g["theta_m_dd"] + u_dd
    return ph.residuals(torch, params, effects, Q_res=Q_res, Q_red=Qm, theta_m_dd=g["theta_m_dd"],
                        theta_f_dd=g["theta_f_dd"], x_FS_dd=x_dd, y_FS_dd=y_dd,
                        F_b=F_b, F_mx=F_mx, F_my=F_my, F_FS=F_FS, Q_out=extra_out)


class PINN(nn.Module):
    """Network + output scaling + physics loss state (lambda_c, residual scaler, parameter calibration).

    ``calibrate`` names physical parameters the PINN identifies jointly with
    the network (the inverse problem): each gets a learnable log-multiplier
    ``c_i`` (p_i = p_i0 exp(c_i)), regularised towards the prior value by
    ``calib_reg * sum c_i^2``; they enter only the physics term.
    """

    def __init__(self, net: TwinLSTM, params: ph.TwinParams, effects, q_mean: float, q_std: float,
                 loss_cfg: LossConfig, extra_terms=(), calibrate=(), calib_reg: float = 1e-2,
                 physpath=None, r_mean: float | None = None, r_std: float | None = None, amp: bool = False):
        super().__init__()
        from .physpath import PhysicsPath  # noqa: PLC0415

        # Q_red = Q_phys + gate * (r_mean + r_std * network output 0): the identified physics path plus
        # the learned remainder (hd_twin.physpath); without a physics path Q_phys = 0 and r = Q_red.
        self.physpath = physpath if physpath is not None else PhysicsPath("none")
        self.r_mean = float(q_mean if r_mean is None else r_mean)
        self.r_std = float(q_std if r_std is None else r_std)
        self.register_buffer("gate", torch.tensor(1.0))
        self.amp = bool(amp)  # mixed precision (float16 autocast) for the network on CUDA
        bad = [n for n in calibrate if n not in ph._BOUNDS or n in ("N", "k_t", "T_ref")]
        if bad:
            raise ValueError(f"cannot calibrate {bad}; choose among {sorted(set(ph._BOUNDS) - {'N', 'k_t', 'T_ref'})}")
        self.calib_names = list(calibrate)
        self.calib_reg = float(calib_reg)
        self.calib = nn.Parameter(torch.zeros(len(self.calib_names)))
        self.extra_terms = list(extra_terms)
        # the declared effects physics evaluates itself (an effect carried by an identified term is not doubled)
        self.declared_effects = list(effects)
        self.net, self.params, self.effects = net, params, ph.equation_effects(effects, self.extra_terms)
        self.q_mean, self.q_std = float(q_mean), float(q_std)
        F_ref = q_std / params.r_m
        self.u_scale = params.mu_g * F_ref / params.k_b  # m
        self.y_scale = F_ref / params.k_FS  # m
        self.cfg = loss_cfg
        self.lam = LambdaC(loss_cfg.lambda_init, loss_cfg.lambda_mode)
        self.scaler = ResidualScaler(ph.residual_scales(params, q_std), loss_cfg.adaptive_scaling, loss_cfg.scale_momentum)

    def physics_params(self) -> ph.TwinParams:
        """Parameters for the physics term (calibrated ones as differentiable tensors)."""
        if not self.calib_names:
            return self.params
        kw = {n: getattr(self.params, n) * torch.exp(self.calib[i]) for i, n in enumerate(self.calib_names)}
        return dataclasses.replace(self.params, **kw)

    def calibrated_params(self) -> ph.TwinParams:
        """The identified parameters as plain floats (validated)."""
        if not self.calib_names:
            return self.params
        c = self.calib.detach().cpu().numpy()
        kw = {n: float(getattr(self.params, n) * np.exp(c[i])) for i, n in enumerate(self.calib_names)}
        return dataclasses.replace(self.params, **kw).validate("calibrated twin parameters")

    def output_scales(self) -> dict:
        """SI = mean + scale * network output, per output channel (Q_red: the learned remainder, before
        the gate; the twin's Q_red adds the physics path)."""
        return {"Q_red": (self.r_mean, self.r_std), "u_FS": (0.0, self.u_scale), "y_FS": (0.0, self.y_scale)}

    def remainder_SI(self, out: torch.Tensor) -> torch.Tensor:
        """The learned remainder [N*m] before the gate."""
        return self.r_mean + self.r_std * out[..., 0]

    def to_SI(self, out: torch.Tensor, q_phys: torch.Tensor | None = None) -> dict:
        q = self.gate * self.remainder_SI(out)
        if q_phys is not None:
            q = q_phys + q
        return {"Q_red": q, "u": self.u_scale * out[..., 1], "y": self.y_scale * out[..., 2]}

    def forward_net(self, x: torch.Tensor, state=None):
        """The network, under float16 autocast on CUDA when ``amp`` (cuDNN LSTM in half precision),
        outputs returned in float32 so the physics residuals stay in full precision."""
        if self.amp and x.is_cuda:
            with torch.autocast(device_type="cuda", dtype=torch.float16):
                out, st = self.net(x, state)
            return out.float(), st
        return self.net(x, state)

    def losses(self, batch: dict, epoch: float = 0.0, physics: bool = True, update_scaler: bool = True) -> dict:
        out, _ = self.forward_net(batch["x"])
        pred = self.to_SI(out, batch.get("Q_phys"))
        mask = batch["mask"].clone()
        mask[:, : self.cfg.washout] = False
        n = mask.sum().clamp_min(1)
        err = torch.where(mask, (pred["Q_red"] - torch.nan_to_num(batch["Q_red"])) / self.q_std, torch.zeros_like(out[..., 0]))
        L_d = (err**2).sum() / n
        res = {"L_d": L_d, "pred": pred}
        use_phys = physics and (self.lam.mode != "fixed" or self.lam.init > 0)
        if physics:
            r = physics_residuals_torch(pred, batch, self.physics_params(), self.effects, self.extra_terms)
            m = mask[:, 1:-1]
            nm = m.sum().clamp_min(1)
            R = torch.stack(r)  # [4, B, T-2]
            ms = torch.where(m, R, torch.zeros_like(R)).pow(2).sum(dim=(1, 2)) / nm  # [4] mean squares, SI^2
            rms = ms.sqrt()
            # the scales follow the residuals while the physics is ramped in (the first epoch
            # without a ramp) and are then frozen: a scale that kept shrinking with the residuals
            # would amplify the physics gradient without bound and trade data accuracy for it
            if update_scaler and self.training and epoch < max(1, self.cfg.ramp_epochs):
                self.scaler.update(rms)
            L_c = (ms / self.scaler.scales().pow(2)).mean()
            L_c_ref = (ms.detach() / self.scaler.fixed.pow(2)).mean()
            res.update(L_c=L_c, L_c_ref=L_c_ref, r_rms=rms.detach())
        ramp = ramp_factor(epoch, self.cfg.ramp_epochs)
        res["ramp"] = ramp
        lam_v = self.lam.value().detach()  # a tensor: no device synchronisation per step
        res["lambda_c"] = lam_v
        if use_phys:
            res["L_tot"] = self.lam.total(L_d, res["L_c"], ramp)
            if self.calib_names:
                res["L_tot"] = res["L_tot"] + self.calib_reg * (self.calib**2).sum()
            res["L_tot_report"] = (L_d + lam_v * res["L_c_ref"]).detach()
        else:
            res["L_tot"] = self.lam.total(L_d, None)
            res["L_tot_report"] = L_d.detach()
        return res
