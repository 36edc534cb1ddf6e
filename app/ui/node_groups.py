"""Objects packed into a few shared scene nodes: fixed groups of at most ``size`` objects per category.

viser's cost is per scene node (a handle built, its properties' type hints read, a message queued and
replayed to every joining browser), not per segment: a site of 2,000 objects drawn as one node per
object took 5.5–10.7 s to draw and froze the video meanwhile. Grouped, a full draw is a few dozen
nodes, and a change to one object resends only its group's arrays. An object keeps its group while
it stays in its category (its status colour, say), so the other groups are left untouched.
"""

from __future__ import annotations

from collections.abc import Hashable

__all__ = ["NodeGroups"]


class NodeGroups:
    """Which group each object's content lives in.

    ``place(obj_id, category)`` puts an object in a group of that category (keeping its group when it
    is already in one of that category) and returns the groups whose content changed; ``drop(obj_id)``
    takes it out. A group is ``(category, index)``; ``members(group)`` lists its objects in a stable order.
    """

    def __init__(self, size: int):
        if size < 1:
            raise ValueError(f"a group holds at least one object, got size {size}")
        self.size = int(size)
        self._where: dict[Hashable, tuple] = {}  # object id → group
        self._members: dict[tuple, list] = {}  # group → object ids

    def place(self, obj_id: Hashable, category: Hashable) -> set[tuple]:
        """Put ``obj_id`` in a group of ``category``; the groups touched (its old one too if it moved)."""
        old = self._where.get(obj_id)
        if old is not None and old[0] == category:
            return {old}
        touched = set() if old is None else {self.drop(obj_id)}
        index = 0
        while len(self._members.get((category, index), ())) >= self.size:
            index += 1
        group = (category, index)
        self._members.setdefault(group, []).append(obj_id)
        self._where[obj_id] = group
        return touched | {group}

    def drop(self, obj_id: Hashable) -> tuple | None:
        """Take ``obj_id`` out of its group; that group, or None if it was in none."""
        group = self._where.pop(obj_id, None)
        if group is not None:
            members = self._members[group]
            members.remove(obj_id)
            if not members:
                del self._members[group]
        return group

    def group_of(self, obj_id: Hashable) -> tuple | None:
        return self._where.get(obj_id)

    def groups(self) -> set[tuple]:
        return set(self._members)

    def members(self, group: tuple) -> list:
        return list(self._members.get(group, ()))

    def __len__(self) -> int:
        return len(self._members)
