"""Telling several session observers (see ``scenarios.runner.SessionObserver``) in turn."""


class Observers:
    """Several observers told in turn, for a run that both records and writes bags."""

    def __init__(self, *observers):
        self.observers = [o for o in observers if o is not None]

    def session_start(self, *args) -> None:
        for o in self.observers:
            o.session_start(*args)

    def scan(self, *args) -> None:
        for o in self.observers:
            o.scan(*args)

    def session_end(self, result) -> None:
        for o in self.observers:
            o.session_end(result)
