"""Adam over stacked parameters whose leading axis is the member: S independent Adams in one.

Adam acts element by element, so one Adam over the stacked tensors, fed the gradient of the members'
summed losses, moves each member as its own Adam would, but for one thing: a member that skips an
update (SB3's ``train`` skips a batch with nothing labelled in it) must not move, and its step count
must not advance. Hence this small optimizer, with a step count per member, rather than ``torch.optim.Adam``.
"""

from __future__ import annotations

from collections.abc import Iterable

import torch as th


class StackedAdam:
    """Adam (Kingma and Ba, 2015) on parameters of shape (S, ...), with a step count per member.

    The arithmetic is ``torch.optim.Adam``'s (no weight decay, no amsgrad), so one member's updates
    equal a ``torch.optim.Adam``'s on that member's slice to float32 rounding.

    :param params: the stacked parameters, each with the members on axis 0.
    :param lr: the learning rate.
    :param betas: the decay rates of the first and second moments.
    :param eps: added to the denominator.
    """

    def __init__(
        self,
        params: Iterable[th.Tensor],
        lr: float,
        betas: tuple[float, float] = (0.9, 0.999),
        eps: float = 1e-8,
    ) -> None:
        self.params = list(params)
        self.lr, self.betas, self.eps = float(lr), betas, float(eps)
        n = int(self.params[0].shape[0])
        self.steps = th.zeros(n, dtype=th.float64, device=self.params[0].device)
        """(S,) the updates each member has taken."""
        self.exp_avg = [th.zeros_like(p) for p in self.params]
        self.exp_avg_sq = [th.zeros_like(p) for p in self.params]

    def _index(self, param: th.Tensor) -> int:
        return next(i for i, p in enumerate(self.params) if p is param)

    @th.no_grad()
    def set_member(
        self, param: th.Tensor, member: int, step: float, exp_avg: th.Tensor, exp_avg_sq: th.Tensor
    ) -> None:
        """Member ``member``'s state for ``param`` from one ``torch.optim.Adam``'s: its step count and
        the moments of the matching unstacked parameter (an ``nn.Linear``'s (out, in) weight is
        transposed to the stack's (in, out); a bias gains the stack's middle axis)."""
        k = self._index(param)
        shape = self.exp_avg[k].shape[1:]
        for mine, theirs in ((self.exp_avg[k], exp_avg), (self.exp_avg_sq[k], exp_avg_sq)):
            mine[member] = (theirs.T if theirs.dim() == 2 else theirs).reshape(shape)
        self.steps[member] = step

    @th.no_grad()
    def member_state(self, param: th.Tensor, member: int, shape: tuple[int, ...]) -> dict[str, th.Tensor]:
        """Member ``member``'s state for ``param`` as one ``torch.optim.Adam``'s for the matching
        unstacked parameter of shape ``shape`` (the inverse of :meth:`set_member`)."""
        k = self._index(param)
        moments = []
        for stacked in (self.exp_avg[k], self.exp_avg_sq[k]):
            value = stacked[member].clone()
            moments.append(value.T.contiguous() if len(shape) == 2 else value.reshape(shape))
        step = th.tensor(float(self.steps[member]), dtype=th.float32)
        return {"step": step, "exp_avg": moments[0], "exp_avg_sq": moments[1]}

    @th.no_grad()
    def step(self, active: th.Tensor) -> None:
        """One update of the members where ``active`` (S,) bool is set, from the parameters' ``grad``;
        the others are left exactly as they were."""
        beta1, beta2 = self.betas
        self.steps += active.to(th.float64)
        correction1 = 1 - beta1**self.steps
        correction2_sqrt = (1 - beta2**self.steps).sqrt()
        every = bool(active.all())  # the common case: no member skips, so no masking
        for p, m, v in zip(self.params, self.exp_avg, self.exp_avg_sq, strict=True):
            if p.grad is None:
                continue
            shape = (-1,) + (1,) * (p.dim() - 1)
            grad = p.grad
            correction = correction2_sqrt.to(p.dtype).view(shape).clamp_min(1e-30)
            step_size = (self.lr / correction1.clamp_min(1e-30)).to(p.dtype).view(shape)
            if every:
                m.lerp_(grad, 1 - beta1)
                v.mul_(beta2).addcmul_(grad, grad, value=1 - beta2)
                p.sub_(step_size * (m / (v.sqrt() / correction).add_(self.eps)))
                continue
            on = active.view(shape)
            m.copy_(th.where(on, m.lerp(grad, 1 - beta1), m))
            v.copy_(th.where(on, v * beta2 + (1 - beta2) * (grad * grad), v))
            denom = (v.sqrt() / correction).add_(self.eps)
            p.copy_(th.where(on, p - step_size * (m / denom), p))
