"""The lifecycle node's services and transition events, served with rclpy's public API only.

rclpy's own change_state service raises inside the executor for a transition the current
state does not have (activate before configure), which ends the process. So the node is made
without rclpy's communication interface (``enable_communication_interface=False``) and this
module serves the same five services and the ``~/transition_event`` topic, on the standard
state machine of ROS 2's managed nodes (design.ros2.org, "Managed nodes"): a transition that
is not available is answered ``success: false`` and the node goes on, as a lifecycle manager
expects; an available one runs through rclpy's public ``trigger_*`` methods."""

from __future__ import annotations

from lifecycle_msgs.msg import State, Transition, TransitionDescription, TransitionEvent
from lifecycle_msgs.srv import (ChangeState, GetAvailableStates, GetAvailableTransitions,
                                GetState)
from rclpy.lifecycle import TransitionCallbackReturn

PRIMARY = {"unconfigured": State.PRIMARY_STATE_UNCONFIGURED,
           "inactive": State.PRIMARY_STATE_INACTIVE, "active": State.PRIMARY_STATE_ACTIVE,
           "finalized": State.PRIMARY_STATE_FINALIZED}
# transition -> (label, from, through, to, its result transitions' name)
TRANSITIONS = {
    Transition.TRANSITION_CONFIGURE: ("configure", "unconfigured", "configuring", "inactive",
                                      "CONFIGURE"),
    Transition.TRANSITION_CLEANUP: ("cleanup", "inactive", "cleaningup", "unconfigured",
                                    "CLEANUP"),
    Transition.TRANSITION_ACTIVATE: ("activate", "inactive", "activating", "active",
                                     "ACTIVATE"),
    Transition.TRANSITION_DEACTIVATE: ("deactivate", "active", "deactivating", "inactive",
                                       "DEACTIVATE"),
    Transition.TRANSITION_UNCONFIGURED_SHUTDOWN: ("shutdown", "unconfigured", "shuttingdown",
                                                  "finalized", "SHUTDOWN"),
    Transition.TRANSITION_INACTIVE_SHUTDOWN: ("shutdown", "inactive", "shuttingdown",
                                              "finalized", "SHUTDOWN"),
    Transition.TRANSITION_ACTIVE_SHUTDOWN: ("shutdown", "active", "shuttingdown", "finalized",
                                            "SHUTDOWN"),
}
TRANSITION_STATES = {"configuring": State.TRANSITION_STATE_CONFIGURING,
                     "cleaningup": State.TRANSITION_STATE_CLEANINGUP,
                     "shuttingdown": State.TRANSITION_STATE_SHUTTINGDOWN,
                     "activating": State.TRANSITION_STATE_ACTIVATING,
                     "deactivating": State.TRANSITION_STATE_DEACTIVATING,
                     "errorprocessing": State.TRANSITION_STATE_ERRORPROCESSING}
RESULT = {TransitionCallbackReturn.SUCCESS: "SUCCESS", TransitionCallbackReturn.FAILURE:
          "FAILURE", TransitionCallbackReturn.ERROR: "ERROR"}


def _state(label: str) -> State:
    return State(id={**PRIMARY, **TRANSITION_STATES}[label], label=label)


class Lifecycle:
    """The lifecycle interface of ``node`` (a ``rclpy.lifecycle.LifecycleNode`` made with
    ``enable_communication_interface=False``)."""

    def __init__(self, node):
        self.node = node
        self.state = "unconfigured"
        self._events = node.create_publisher(TransitionEvent, "~/transition_event", 10)
        for srv, name, handler in (
                (ChangeState, "change_state", self._on_change_state),
                (GetState, "get_state", self._on_get_state),
                (GetAvailableStates, "get_available_states", self._on_get_available_states),
                (GetAvailableTransitions, "get_available_transitions",
                 self._on_get_available_transitions),
                (GetAvailableTransitions, "get_transition_graph", self._on_get_graph)):
            node.create_service(srv, f"~/{name}", handler)

    def available(self) -> list[int]:
        return [t for t, (_, start, *_rest) in TRANSITIONS.items() if start == self.state]

    def change(self, transition: int) -> bool:
        """Run ``transition``; whether it succeeded. One the current state does not have is
        refused, said in the log."""
        if transition not in self.available():
            self.node.get_logger().warn(f"transition {transition} refused: not available in "
                                        f"state '{self.state}'")
            return False
        label, start, through, goal, name = TRANSITIONS[transition]
        self._event(transition, label, start, through)
        trigger = {"configure": self.node.trigger_configure,
                   "cleanup": self.node.trigger_cleanup,
                   "activate": self.node.trigger_activate,
                   "deactivate": self.node.trigger_deactivate,
                   "shutdown": self.node.trigger_shutdown}[label]
        result = trigger()
        # rclpy's state machine moves so: success to the goal, failure back to the start, an
        # error through on_error (which succeeds) to unconfigured
        end = {TransitionCallbackReturn.SUCCESS: goal,
               TransitionCallbackReturn.FAILURE: start}.get(result, "unconfigured")
        if label == "shutdown":
            end = "finalized"
        done = getattr(Transition, f"TRANSITION_ON_{name}_{RESULT[result]}")
        self._event(done, RESULT[result].lower(), through, end)
        self.state = end
        return result == TransitionCallbackReturn.SUCCESS

    def _event(self, transition: int, label: str, start: str, goal: str) -> None:
        event = TransitionEvent()
        event.timestamp = self.node.get_clock().now().nanoseconds
        event.transition = Transition(id=transition, label=label)
        event.start_state, event.goal_state = _state(start), _state(goal)
        self._events.publish(event)

    def _on_change_state(self, request, response):
        transition = request.transition.id
        if request.transition.label:
            named = [t for t in self.available() if TRANSITIONS[t][0] == request.transition.label]
            transition = named[0] if named else -1
        response.success = self.change(transition)
        return response

    def _on_get_state(self, _request, response):
        response.current_state = _state(self.state)
        return response

    def _on_get_available_states(self, _request, response):
        response.available_states = [_state(label) for label in (*PRIMARY, *TRANSITION_STATES)]
        return response

    def _on_get_available_transitions(self, _request, response):
        response.available_transitions = [self._description(t) for t in self.available()]
        return response

    def _on_get_graph(self, _request, response):
        response.available_transitions = [self._description(t) for t in TRANSITIONS]
        return response

    @staticmethod
    def _description(t: int) -> TransitionDescription:
        label, start, _, goal, _ = TRANSITIONS[t]
        return TransitionDescription(transition=Transition(id=t, label=label),
                                     start_state=_state(start), goal_state=_state(goal))
