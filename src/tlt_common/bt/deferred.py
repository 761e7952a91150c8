"""A Sequence whose children are built when they are first needed.

An ARS builds a request's whole branch (an Add Member is over a hundred behaviours) on the tick the
request arrives, and the CRS waits for that tick's feedback. A phase the request reaches only
minutes later can be built just after: :class:`DeferredSequence` stands in for it, named as the
phase, with no children until :meth:`DeferredSequence.build` (the tree calls it on its next tick)
or its own first tick builds them. Once built it is the phase: same name, same children, same
paths below it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import py_trees
from py_trees.common import Status


class DeferredSequence(py_trees.composites.Sequence):
    """Sequence with memory whose children come from ``make`` (which returns a Sequence with
    memory named ``name``; its children are moved here). A ``make`` that raises leaves the node
    childless; ticked, it then fails with the error as its feedback.
    """

    def __init__(self, name: str, make: Callable[[], py_trees.composites.Sequence]) -> None:
        super().__init__(name, memory=True)
        self._make: Callable[[], py_trees.composites.Sequence] | None = make
        self.error = ""

    @property
    def built(self) -> bool:
        return self._make is None

    def build(self) -> bool:
        """Build the children if not yet done; True when this call built them."""
        if self._make is None:
            return False
        make, self._make = self._make, None
        try:
            made = make()
            sequence = isinstance(made, py_trees.composites.Sequence) and made.memory
            if not sequence or made.name != self.name:
                raise TypeError(
                    f"expected a Sequence with memory named '{self.name}', got "
                    f"{type(made).__name__} '{made.name}'"
                )
        except Exception as exc:  # reported when ticked, as any failing step is
            self.error = f"cannot build '{self.name}': {exc}"
            return True
        children = list(made.children)
        for child in children:
            made.remove_child(child)
        self.add_children(children)
        return True

    def tick(self) -> Iterator[py_trees.behaviour.Behaviour]:
        self.build()
        if self.error:
            self.feedback_message = self.error
            self.stop(Status.FAILURE)
            yield self
            return
        yield from super().tick()


def build_deferred(root: py_trees.behaviour.Behaviour) -> bool:
    """Build every :class:`DeferredSequence` under ``root`` (those inside built ones too); True
    when any was built, so the tree's shape changed."""
    changed = False
    while pending := [n for n in root.iterate() if isinstance(n, DeferredSequence) and not n.built]:
        for node in pending:
            node.build()
        changed = True
    return changed
