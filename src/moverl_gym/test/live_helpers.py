"""Assertions and a rollout shared by the live (rostest) tests of the shield and the env."""


class LiveAssertions:
    """Mixin for unittest.TestCase classes that step the live shield or env."""

    def assert_no_contacts(self, res, substeps=True):
        """The simulator measured contacts for the step and found none."""
        self.assertTrue(res.contacts.available)
        self.assertEqual(res.contacts.world_contacts + res.contacts.self_contacts, 0, res.contacts.pairs)
        if substeps:
            self.assertEqual(res.contacts.substeps_in_contact, 0)

    def random_rollout_without_contact(self, env, steps, near):
        """Random actions for `steps` env steps, asserting zero contacts at every step; episodes alternate
        between the start `near` (next to the obstacles) and a random start. Returns the verdict counts."""
        counts, episode = {}, 0
        for _ in range(steps):
            _, _, term, trunc, info = env.step(env.action_space.sample())
            self.assertEqual(info["contacts"], 0, info)
            counts[info["verdict"]] = counts.get(info["verdict"], 0) + 1
            if term or trunc:
                episode += 1
                env.reset(options={"start": near} if episode % 2 == 0 else None)
        return counts
