"""A request retried every 10 ms until answered: with /req dropped, a lasso."""

from __future__ import annotations

from dataclasses import dataclass

from twinfleet import Context, Node, String, every, subscribe


@dataclass
class Asked:
    """State of Asker."""

    answered: bool = False


class Asker(Node):
    """Asks on /req every 10 ms until /ans comes."""

    def initial_state(self) -> Asked:
        return Asked()

    @every(10)
    def ask(self, ctx: Context) -> None:
        if not self.state.answered:
            ctx.publish("/req", String("?"))

    @subscribe("/ans")
    def on_ans(self, ctx: Context, msg: String) -> None:
        self.state.answered = True


class Answerer(Node):
    """Answers every /req on /ans."""

    @subscribe("/req")
    def on_req(self, ctx: Context, msg: String) -> None:
        ctx.publish("/ans", String("!"))
