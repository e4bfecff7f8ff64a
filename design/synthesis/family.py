"""A family of identified models, validated once: what every design is made and certified on.

:class:`ModelFamily` is an immutable sequence of models that share one input (the steering rate),
the same outputs, sample time and output normalisation, each of an order the design tools take
(:data:`design.core.limits.MAX_MODEL_ORDER`). The designs take any sequence of models and make it a
family with :func:`as_family`, which returns a family unchanged: a recipe that makes the family once
passes it down without its models being checked again at every step.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field

from identification.model import Model

from design.core.errors import DesignInputError
from design.core.limits import check_model_order

__all__ = ["ModelFamily", "as_family", "model_names"]


def model_names(models: Sequence[Model]) -> list[str]:
    """The models' names (``meta["name"]``, else ``model <i>``), made unique with ``#<i>`` when two repeat."""
    names = [str(m.meta.get("name", f"model {i}")) for i, m in enumerate(models)]
    if len(set(names)) != len(names):
        names = [f"{n}#{i}" for i, n in enumerate(names)]
    return names


@dataclass(frozen=True)
class ModelFamily(Sequence):
    """Models checked to be alike (see module docstring); a sequence of :class:`~identification.model.Model`.

    Raises
    ------
    DesignInputError
        No model; a model whose inputs, outputs, sample time or normalisation differ from the first's
        (naming it); more than one input; an order above the limit.
    """

    models: tuple[Model, ...]
    names: tuple[str, ...] = field(init=False, compare=False)

    def __post_init__(self) -> None:
        models = tuple(self.models)
        if not models:
            raise DesignInputError("no models given")
        if not all(isinstance(m, Model) for m in models):
            raise DesignInputError(f"a model family holds Model objects, got "
                                   f"{sorted({type(m).__name__ for m in models})}")
        m0 = models[0]
        for i, m in enumerate(models):
            if (m.n_inputs, m.n_outputs) != (m0.n_inputs, m0.n_outputs) or abs(m.dt - m0.dt) > 1e-12:
                raise DesignInputError(f"model {i} ({m.meta.get('name')}) has m={m.n_inputs}, q={m.n_outputs}, "
                                       f"dt={m.dt}; expected m={m0.n_inputs}, q={m0.n_outputs}, dt={m0.dt} like the "
                                       "first")
            if m.meta.get("normalization", "velocity") != m0.meta.get("normalization", "velocity"):
                raise DesignInputError(f"model {i} has normalization {m.meta.get('normalization')!r}, "
                                       f"the first has {m0.meta.get('normalization')!r}")
        if m0.n_inputs != 1:
            raise DesignInputError(f"the tractor has one input (steering rate); the models have {m0.n_inputs}")
        check_model_order(models)
        object.__setattr__(self, "models", models)
        object.__setattr__(self, "names", tuple(model_names(models)))

    def __getitem__(self, index):
        return self.models[index]

    def __len__(self) -> int:
        return len(self.models)

    def __iter__(self) -> Iterator[Model]:
        return iter(self.models)


def as_family(models: Sequence[Model]) -> ModelFamily:
    """``models`` as a :class:`ModelFamily` (a family is returned as it is, not checked again)."""
    return models if isinstance(models, ModelFamily) else ModelFamily(tuple(models))
