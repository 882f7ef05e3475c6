"""Training the policy: PPO, curricula, demonstrations, and the bundles a policy is saved in."""
