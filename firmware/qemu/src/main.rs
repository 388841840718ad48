//! Turntable firmware for QEMU's lm3s6965evb: the shared protocol logic
//! ([`turntable_proto::Device`]) served on UART0, with a free-running 64-bit time base and the
//! commanded position driven out as STEP/DIR pulses on GPIO port F (pins 0 and 1).
//!
//! The core sleeps in WFI with PRIMASK set: a pending UART0 or timer 0A interrupt wakes it
//! without running a handler, so QEMU does not spin a host core. Timer 0A only wakes the loop
//! every millisecond. Time itself is QEMU's own clock, read through semihosting's `SYS_ELAPSED`
//! (QEMU must run with `-semihosting-config enable=on,target=native`): like the RP2040's 64-bit
//! microsecond timer, it runs on whether or not the core does, so a vCPU that a busy host
//! deschedules for seconds loses no time. (The board's only readable counter, the 24-bit
//! SysTick, wraps every 1.34 s: read as a difference on every poll it lost a whole period
//! whenever QEMU was descheduled for longer, and a capture then found the device clock
//! contradicting itself by about a second.)
#![no_std]
#![no_main]

use core::ptr::{read_volatile, write_volatile};
use cortex_m::peripheral::NVIC;
use cortex_m_rt::entry;
use panic_halt as _;
use turntable_proto::{Config, Device, Sink};

const UART0: usize = 0x4000_C000;
const DR: usize = 0x000;
const FR: usize = 0x018; // bit 4 RXFE, bit 5 TXFF
const IM: usize = 0x038; // bit 4 RXIM, bit 6 RTIM
const ICR: usize = 0x044;
const UART0_IRQ: u16 = 5;
const SYSCTL_RCGC1: usize = 0x400F_E104;
const TIMER0: usize = 0x4003_0000;
const TIMER_CFG: usize = 0x000;
const TIMER_TAMR: usize = 0x004;
const TIMER_CTL: usize = 0x00C;
const TIMER_IMR: usize = 0x018;
const TIMER_ICR: usize = 0x024;
const TIMER_TAILR: usize = 0x028;
const TIMER0A_IRQ: u16 = 19;
const GPIOF: usize = 0x4002_5000;
const GPIO_DIR: usize = 0x400;
const STEP_PIN: u32 = 1 << 0;
const DIR_PIN: u32 = 1 << 1;
/// Core clock ticks per millisecond, for timer 0A's wake-up. QEMU clocks the lm3s6965evb core
/// at 12.5 MHz out of reset (measured: with 12 000 a SysTick clock ran 4.2 % fast).
const TICKS_PER_MS: u32 = 12_500;

fn reg(addr: usize) -> *mut u32 {
    addr as *mut u32
}

fn putc(b: u8) {
    // SAFETY: UART0 registers of the LM3S6965, accessed only from this single thread.
    unsafe {
        while read_volatile(reg(UART0 + FR)) & (1 << 5) != 0 {}
        write_volatile(reg(UART0 + DR), b as u32);
    }
}

fn getc() -> Option<u8> {
    // SAFETY: as in `putc`.
    unsafe {
        if read_volatile(reg(UART0 + FR)) & (1 << 4) != 0 {
            None
        } else {
            Some(read_volatile(reg(UART0 + DR)) as u8)
        }
    }
}

struct Uart;

impl Sink for Uart {
    fn send(&mut self, line: &str) {
        line.bytes().for_each(putc);
        putc(b'\n');
    }
}

/// Semihosting operations (Arm's semihosting specification).
const SYS_ELAPSED: u32 = 0x30;
const SYS_TICKFREQ: u32 = 0x31;

/// Microsecond clock on QEMU's elapsed-time counter, from its first reading.
struct Clock {
    start: u64,
    per_s: u64,
}

impl Clock {
    fn new() -> Clock {
        // SAFETY: a semihosting call without a parameter block; QEMU answers it (see the
        // module docs), and returns -1 where it cannot.
        let per_s = unsafe { cortex_m::asm::semihosting_syscall(SYS_TICKFREQ, 0) };
        assert!(per_s != u32::MAX && per_s > 0, "semihosting has no tick frequency");
        let mut c = Clock { start: 0, per_s: per_s as u64 };
        c.start = c.ticks();
        c
    }

    fn ticks(&self) -> u64 {
        let mut words = [0u32; 2];
        // SAFETY: SYS_ELAPSED writes two words (low, high) to the block its argument points to.
        let r = unsafe { cortex_m::asm::semihosting_syscall(SYS_ELAPSED, words.as_mut_ptr() as u32) };
        assert!(r == 0, "semihosting SYS_ELAPSED failed");
        (words[1] as u64) << 32 | words[0] as u64
    }

    fn now_us(&mut self) -> u64 {
        let t = self.ticks() - self.start;
        t / self.per_s * 1_000_000 + t % self.per_s * 1_000_000 / self.per_s
    }
}

#[derive(Clone, Copy)]
struct Irq(u16);

// SAFETY: 5 (UART0) and 19 (timer 0A) are interrupt numbers of the LM3S6965.
unsafe impl cortex_m::interrupt::InterruptNumber for Irq {
    fn number(self) -> u16 {
        self.0
    }
}

/// Emits STEP pulses (with DIR) until the motor position reaches the commanded one.
struct Stepper {
    at: i64,
}

impl Stepper {
    fn follow(&mut self, target: i64) {
        while self.at != target {
            let dir = if target > self.at { 1 } else { -1 };
            // SAFETY: GPIO port F data register, bit-masked address for pins 0 and 1.
            unsafe {
                write_volatile(reg(GPIOF + ((STEP_PIN | DIR_PIN) as usize) * 4), if dir > 0 { DIR_PIN } else { 0 });
                write_volatile(
                    reg(GPIOF + ((STEP_PIN | DIR_PIN) as usize) * 4),
                    STEP_PIN | if dir > 0 { DIR_PIN } else { 0 },
                );
            }
            self.at += dir;
        }
    }
}

#[entry]
fn main() -> ! {
    cortex_m::interrupt::disable();
    // SAFETY: enabling UART0 receive interrupts and GPIO F outputs during single-threaded init.
    unsafe {
        write_volatile(reg(UART0 + IM), (1 << 4) | (1 << 6));
        NVIC::unmask(Irq(UART0_IRQ));
        write_volatile(reg(GPIOF + GPIO_DIR), STEP_PIN | DIR_PIN);
    }
    // SAFETY: timer 0 as a 32-bit periodic timer with its time-out interrupt (a wake-up source
    // only), configured while it is disabled, during single-threaded init.
    unsafe {
        write_volatile(reg(SYSCTL_RCGC1), read_volatile(reg(SYSCTL_RCGC1)) | (1 << 16));
        write_volatile(reg(TIMER0 + TIMER_CTL), 0);
        write_volatile(reg(TIMER0 + TIMER_CFG), 0);
        write_volatile(reg(TIMER0 + TIMER_TAMR), 0x2);
        write_volatile(reg(TIMER0 + TIMER_TAILR), TICKS_PER_MS - 1);
        write_volatile(reg(TIMER0 + TIMER_IMR), 1);
        NVIC::unmask(Irq(TIMER0A_IRQ));
        write_volatile(reg(TIMER0 + TIMER_CTL), 1);
    }
    let mut clock = Clock::new();
    let mut dev = Device::new(Config { fw_version: "0.2.0-qemu", ..Config::default() }, 0);
    dev.reset(0, &mut Uart);
    let mut stepper = Stepper { at: 0 };
    loop {
        while let Some(b) = getc() {
            let now = clock.now_us();
            dev.feed(b, now, &mut Uart);
        }
        let now = clock.now_us();
        dev.poll(now, &mut Uart);
        stepper.follow(dev.physical_position(now));
        cortex_m::asm::wfi();
        // SAFETY: clearing UART0 and timer 0A interrupt flags; both only wake WFI.
        unsafe {
            write_volatile(reg(UART0 + ICR), 0x7ff);
            write_volatile(reg(TIMER0 + TIMER_ICR), 1);
        }
        NVIC::unpend(Irq(UART0_IRQ));
        NVIC::unpend(Irq(TIMER0A_IRQ));
    }
}
