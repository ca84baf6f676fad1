"""The topic map (msg_config/topics.yaml): names, types, units, QoS, wiring."""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

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
            per_step=bool(entry["per_step"]))
    return topics


def step_topics() -> list[Topic]:
    """Topics carrying exactly one message per lockstep step, in map order."""
    return [topic for topic in topic_map().values() if topic.per_step]
