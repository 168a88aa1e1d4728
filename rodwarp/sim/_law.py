"""The contact law's base class and the registry it is listed in (:data:`CONTACT_LAWS`,
:func:`register_contact_law`); the laws themselves are ``law_<name>.py`` and the built-in ones
are listed in :mod:`rodwarp.sim.contact_law`."""

from __future__ import annotations

from dataclasses import dataclass, fields
from types import ModuleType
from typing import ClassVar

from rodwarp.errors import RodwarpError, RodwarpTypeError

#: the registered laws by name (:func:`register_contact_law`)
CONTACT_LAWS: dict[str, type] = {}
#: their device tags (the index of their device module in kernels/contact_laws.py)
_TAGS: dict[str, int] = {}


class _Tagged(type):
    """Lets ``ContactLaw(name, **parameters)`` build the registered law of that name."""

    def __call__(cls, *args, **kwargs):
        if cls is ContactLaw:
            return ContactLaw.from_tag(*args, **kwargs)
        return super().__call__(*args, **kwargs)


@dataclass(frozen=True)
class ContactLaw(metaclass=_Tagged):
    """The contact law of a :class:`~rodwarp.sim.Model`: the base of every law's host class.

    ``ContactLaw(name, **parameters)`` is :meth:`from_tag`. A subclass sets the class
    attributes below and overrides the methods its law needs.

    Attributes
    ----------
    name : str
        The law's tag (``exact``, ``imc``).
    device : module
        Its device module (:mod:`rodwarp.kernels.contact_laws` states the interface).
    projects_overlaps : bool
        Whether the solver's post-stabilisation removes overlaps after a step (a penalty
        law's overlap is its compliance, not an error).
    """

    name: ClassVar[str] = ""
    device: ClassVar[ModuleType | None] = None
    projects_overlaps: ClassVar[bool] = True

    @staticmethod
    def from_tag(name: str = "exact", **parameters) -> ContactLaw:
        """The registered law called ``name`` with these parameters (its class's fields).

        Raises
        ------
        TypeError
            ``name`` not a string, or a parameter the law does not have.
        RodwarpError
            An unknown law, or a parameter out of its range.
        """
        if not isinstance(name, str):
            raise RodwarpTypeError(f"name must be one of {', '.join(CONTACT_LAWS)}, got "
                                   f"{type(name).__name__} {name!r}")
        if name not in CONTACT_LAWS:
            raise RodwarpError(f"contact law must be {' or '.join(CONTACT_LAWS)}, got '{name}'")
        return CONTACT_LAWS[name](**parameters)

    @classmethod
    def parameters(cls) -> dict:
        """The law's parameters and their defaults (None: filled in by :meth:`resolved`), for
        option tables and ``from_tag``."""
        return {f.name: f.default for f in fields(cls)}

    @property
    def tag(self) -> int:
        """The law's device tag (``StepParams.law``)."""
        return _TAGS[self.name]

    def resolved(self, min_diameter: float, rod_weight: float) -> ContactLaw:
        """This law with its defaults filled in for a scene of rods at least ``min_diameter``
        (m) thick whose heaviest rod weighs ``rod_weight`` (N)."""
        return self

    def reach(self) -> float:
        """Surface gap (m) below which the law may act: contacts must be found there (the
        model's contact distance is raised to it). 0: only at touching."""
        return 0.0

    def device_params(self) -> tuple:
        """The parameters as the device module reads them (up to 8 floats, the rest 0)."""
        return ()

    def describe(self) -> str:
        """One line naming the law and its parameters (for summaries and figures)."""
        return self.name

    def to_dict(self) -> dict:
        """The law and its parameters, for summaries (``name`` and each parameter with its unit)."""
        return {"name": self.name}


def register_contact_law(cls: type) -> type:
    """Add a law's host class to :data:`CONTACT_LAWS` and its device module to the kernels'
    dispatch (its device tag: the registration order). Usable as a class decorator; register
    every law before the first :class:`~rodwarp.sim.RodSolver` is made.

    Raises
    ------
    RodwarpError
        Not a :class:`ContactLaw` subclass with a name and a device module, or a second law
        of the same name.
    """
    if not (isinstance(cls, type) and issubclass(cls, ContactLaw) and cls.name and cls.device is not None):
        raise RodwarpError(f"a contact law is a ContactLaw subclass with a name and a device module, got {cls!r}")
    if CONTACT_LAWS.get(cls.name, cls) is not cls:
        raise RodwarpError(f"a contact law named '{cls.name}' is already registered")
    from rodwarp.kernels import contact_laws

    try:
        _TAGS[cls.name] = contact_laws.register(cls.device)
    except RuntimeError as e:
        raise RodwarpError(str(e)) from None
    CONTACT_LAWS[cls.name] = cls
    return cls
