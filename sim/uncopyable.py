"""Objects that refuse to be copied or pickled, saying what to do instead."""

from __future__ import annotations

__all__ = ["Uncopyable"]


class Uncopyable:
    """Refuse ``copy.copy``, ``copy.deepcopy`` and ``pickle`` with a ``TypeError``.

    For objects bound to a PyBullet server: a copy would share the server (two owners
    stepping one simulation), and a copy of ``BulletClient`` disconnects the server when
    it is garbage-collected - a refused copy half done used to disconnect the original.
    The refusal comes before anything is copied. ``copy_advice`` says what to do instead.

    Examples
    --------
    >>> import copy
    >>> class Server(Uncopyable):
    ...     copy_advice = "make a new one"
    >>> copy.deepcopy(Server())
    Traceback (most recent call last):
    ...
    TypeError: Server cannot be copied or pickled: make a new one
    """

    copy_advice = "it is bound to a PyBullet server"

    def __copy__(self):
        self._refuse_copy()

    def __deepcopy__(self, memo):
        self._refuse_copy()

    def __reduce_ex__(self, protocol):
        self._refuse_copy()

    def __reduce__(self):
        self._refuse_copy()

    def _refuse_copy(self):
        raise TypeError(f"{type(self).__name__} cannot be copied or pickled: {self.copy_advice}")
