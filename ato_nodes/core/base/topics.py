"""The topic map (msg_config/topics.yaml): names, types, units, QoS, wiring."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import yaml

from .paths import config_dir


@dataclass(frozen=True)
class Topic:
    key: str
    name: str
    type: str
    unit: str
    publishers: tuple[str, ...]
    subscribers: tuple[str, ...]
    qos: str
    per_step: bool
    when: str  # the boolean parameter it exists with ('' = always)

    def exists(self, values: Mapping[str, Any] | None) -> bool:
        """Whether a run of `values` has this topic (None: the topics every run has)."""
        if not self.when:
            return True
        return values is not None and bool(values[self.when])


@lru_cache(maxsize=None)
def topic_map() -> dict[str, Topic]:
    document = yaml.safe_load((config_dir() / "topics.yaml").read_text())
    topics = {}
    for key, entry in document["topics"].items():
        publishers = entry["publisher"]
        topics[key] = Topic(
            key=key, name=entry["name"], type=entry["type"], unit=entry["unit"],
            publishers=tuple(publishers) if isinstance(publishers, list) else (publishers,),
            subscribers=tuple(entry["subscribers"]), qos=entry["qos"],
            per_step=bool(entry["per_step"]), when=entry.get("when", ""))
    return topics


def step_topics(values: Mapping[str, Any] | None = None) -> list[Topic]:
    """Topics carrying exactly one message per lockstep step in a run of `values` (None:
    those every run has), in map order."""
    return [topic for topic in topic_map().values() if topic.per_step and topic.exists(values)]
